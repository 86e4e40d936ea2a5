#!/usr/bin/python3
"""Writes small ROS1 bags with Debian's python3-rosbag, an implementation independent of evloc's
reader, for the bag tests (core/events/rosbag_test.cc, core/dataset/rosbag_dataset_test.cc).

Usage: write_test_bags.py OUT_DIR
       write_test_bags.py --bench EVENTS OUT_DIR   (bench_none.bag and bench_lz4.bag for
       bench/events_benchmark.cc: EVENTS DAVIS240-like events on /dvs/events in messages of
       1,000; payloads packed with numpy, written raw by rosbag)
       write_test_bags.py --small OUT_DIR   (the same topics with at most 8 events per message,
       two messages per topic and no images: fuzzing seeds of 2-4 KB, test_<compression>.bag)
       write_test_bags.py --from-dataset DIR OUT.bag [OFFSET_S]   (an lz4 bag of a dataset folder
       with events.txt, calib.yaml (pinhole or radtan) and groundtruth.txt: /dvs/events in
       messages of 1 ms, /dvs/camera_info, /optitrack/davis, and the images of its images.txt
       on /dvs/image_raw (mono8 or rgb8 as stored, read with python3-pil); for
       tests/bag_end_to_end_test.cc; every
       time moved by the whole seconds OFFSET_S, default 0: ROS's C++ rosbag play refuses record
       times of 0, where a simulated sequence starts; ros/tests/ros_node_test.py)

Message classes come from genpy.dynamic (the ROS message generator, fed the message
definitions below), so the payload serialization is genpy's, not evloc's. Writes, for each
compression none / bz2 / lz4, OUT_DIR/test_<compression>.bag with the topics
  /dvs/events         dvs_msgs/EventArray (240x180)
  /prophesee/events   prophesee_event_msgs/EventArray (640x480)
  /packets/mono       event_camera_msgs/EventPacket, encoding mono
  /packets/evt3       event_camera_msgs/EventPacket, encoding evt3
  /dvs/image_raw      sensor_msgs/Image (mono8, 240x180)
  /dvs/camera_info    sensor_msgs/CameraInfo (plumb_bob)
  /optitrack/davis    geometry_msgs/PoseStamped
and text files with what was written: expected_<topic name>.txt (`t_ns x y p` per event,
`t_ns tx ty tz qx qy qz qw` per pose, `t_ns width height encoding sum` per image with the sum
of its bytes, and the camera).
"""

import os
import random
import struct
import sys

import genpy
import genpy.dynamic
import rosbag

SEP = "\n" + "=" * 80 + "\n"
HEADER = "MSG: std_msgs/Header\nuint32 seq\ntime stamp\nstring frame_id\n"
EVENT = "uint16 x\nuint16 y\ntime ts\nbool polarity\n"
DEFINITIONS = {
    "dvs_msgs/EventArray": "Header header\nuint32 height\nuint32 width\nEvent[] events\n"
    + SEP + HEADER + SEP + "MSG: dvs_msgs/Event\n" + EVENT,
    "prophesee_event_msgs/EventArray": "Header header\nuint32 height\nuint32 width\nEvent[] events\n"
    + SEP + HEADER + SEP + "MSG: prophesee_event_msgs/Event\n" + EVENT,
    "event_camera_msgs/EventPacket": "Header header\nuint32 height\nuint32 width\nuint64 seq\n"
    "uint64 time_base\nstring encoding\nbool is_bigendian\nuint8[] events\n" + SEP + HEADER,
    "sensor_msgs/Image": "Header header\nuint32 height\nuint32 width\nstring encoding\n"
    "uint8 is_bigendian\nuint32 step\nuint8[] data\n" + SEP + HEADER,
    "sensor_msgs/CameraInfo": "Header header\nuint32 height\nuint32 width\n"
    "string distortion_model\nfloat64[] D\nfloat64[9] K\nfloat64[9] R\nfloat64[12] P\n"
    "uint32 binning_x\nuint32 binning_y\nRegionOfInterest roi\n" + SEP + HEADER + SEP
    + "MSG: sensor_msgs/RegionOfInterest\nuint32 x_offset\nuint32 y_offset\nuint32 height\n"
    "uint32 width\nbool do_rectify\n",
    "geometry_msgs/PoseStamped": "Header header\nPose pose\n" + SEP + HEADER + SEP
    + "MSG: geometry_msgs/Pose\nPoint position\nQuaternion orientation\n" + SEP
    + "MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n" + SEP
    + "MSG: geometry_msgs/Quaternion\nfloat64 x\nfloat64 y\nfloat64 z\nfloat64 w\n",
}


def classes(type_name):
    return genpy.dynamic.generate_dynamic(type_name, DEFINITIONS[type_name])


T0_NS = 1_468_939_993_000_000_000  # 2016-07-19, like the Event Camera Dataset


def ros_time(t_ns):
    return genpy.Time(t_ns // 1_000_000_000, t_ns % 1_000_000_000)


def header(cls, seq, t_ns):
    return cls["std_msgs/Header"](seq=seq, stamp=ros_time(t_ns), frame_id="davis")


def evt3_words(events):
    """EVT 3.0 words for events sorted by time (microsecond resolution): TIME_HIGH, TIME_LOW,
    ADDR_Y, ADDR_X per event."""
    words = []
    for t_us, x, y, p in events:
        words.append(0x8000 | ((t_us >> 12) & 0xFFF))
        words.append(0x6000 | (t_us & 0xFFF))
        words.append(0x0000 | (y & 0x7FF))
        words.append(0x2000 | ((1 if p > 0 else 0) << 11) | (x & 0x7FF))
    return struct.pack("<%dH" % len(words), *words)


class RawType:
    """What rosbag.Bag.write(raw=True) needs of a message class for a type it cannot import."""

    def __init__(self, type_name):
        cls = classes(type_name)[type_name]
        self._md5sum = cls._md5sum
        self._full_text = cls._full_text


def write_bench_bags(count, out):
    import numpy

    per_message = 1000
    event = numpy.dtype([("x", "<u2"), ("y", "<u2"), ("s", "<u4"), ("ns", "<u4"), ("p", "u1")])
    raw_type = RawType("dvs_msgs/EventArray")
    i = numpy.arange(count, dtype=numpy.uint64)
    t = T0_NS + numpy.cumsum((i * 2654435761) % 3000)
    events = numpy.zeros(count, dtype=event)
    events["x"], events["y"] = i * 31 % 240, i * 17 % 180
    events["s"], events["ns"] = t // 1_000_000_000, t % 1_000_000_000
    events["p"] = (i * 7 % 3) != 0
    for compression in ("none", "lz4"):
        with rosbag.Bag("%s/bench_%s.bag" % (out, compression), "w",
                        compression=compression) as bag:
            for m, start in enumerate(range(0, count, per_message)):
                block = events[start:start + per_message]
                stamp = int(t[start])
                data = struct.pack("<IIII5sIII", m, stamp // 1_000_000_000, stamp % 1_000_000_000,
                                   5, b"davis", 180, 240, len(block)) + block.tobytes()
                bag.write("/dvs/events", ("dvs_msgs/EventArray", data, raw_type._md5sum, raw_type),
                          t=ros_time(stamp), raw=True)


def write_dataset_bag(folder, out, offset_ns=0):
    import yaml

    dvs = classes("dvs_msgs/EventArray")
    cam = classes("sensor_msgs/CameraInfo")
    pose = classes("geometry_msgs/PoseStamped")
    with open(folder + "/calib.yaml") as handle:
        calib = yaml.safe_load(handle)
    messages = []
    # The camera: evloc's calib.yaml keys (docs/camera.md).
    distortion = [float(value) for value in calib.get("distortion", [])]
    model = {"pinhole": "plumb_bob", "radtan": "plumb_bob", "equidistant": "equidistant"}
    fx, fy, cx, cy = (float(value) for value in calib["intrinsics"])
    messages.append((0, "/dvs/camera_info", lambda t: cam["sensor_msgs/CameraInfo"](
        header=header(cam, 0, t), height=int(calib["height"]), width=int(calib["width"]),
        distortion_model=model[calib["model"]], D=distortion or [0.0] * 5,
        K=[fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0], R=[1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0],
        P=[fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0], binning_x=0, binning_y=0,
        roi=cam["sensor_msgs/RegionOfInterest"]())))
    seconds_to_ns = lambda text: offset_ns + int(text.split(".")[0]) * 1_000_000_000 + int(
        (text.split(".") + [""])[1].ljust(9, "0")[:9])
    with open(folder + "/groundtruth.txt") as handle:
        for m, line in enumerate(l for l in handle if l.strip() and not l.startswith("#")):
            t, x, y, z, qx, qy, qz, qw = line.split()
            t_ns = seconds_to_ns(t)
            messages.append((t_ns, "/optitrack/davis", pose["geometry_msgs/PoseStamped"](
                header=header(pose, m, t_ns), pose=pose["geometry_msgs/Pose"](
                    position=pose["geometry_msgs/Point"](x=float(x), y=float(y), z=float(z)),
                    orientation=pose["geometry_msgs/Quaternion"](
                        x=float(qx), y=float(qy), z=float(qz), w=float(qw))))))
    img = classes("sensor_msgs/Image")
    images_txt = os.path.join(folder, "images.txt")
    if os.path.exists(images_txt):
        from PIL import Image
        with open(images_txt) as handle:
            for m, line in enumerate(l for l in handle if l.strip() and not l.startswith("#")):
                t, path = line.split()[:2]
                t_ns = seconds_to_ns(t)
                picture = Image.open(os.path.join(folder, path))
                encoding = {"L": "mono8", "RGB": "rgb8"}[picture.mode]
                channels = 1 if encoding == "mono8" else 3
                messages.append((t_ns, "/dvs/image_raw", img["sensor_msgs/Image"](
                    header=header(img, m, t_ns), height=picture.height, width=picture.width,
                    encoding=encoding, is_bigendian=0, step=picture.width * channels,
                    data=picture.tobytes())))
    block, block_start = [], None

    def flush():
        t_ns = block[-1].ts.to_nsec()
        messages.append((t_ns, "/dvs/events", dvs["dvs_msgs/EventArray"](
            header=header(dvs, len(messages), t_ns), height=int(calib["height"]),
            width=int(calib["width"]), events=list(block))))

    with open(folder + "/events.txt") as handle:
        for line in handle:
            if not line.strip() or line.startswith("#"):
                continue
            t, x, y, p = line.split()
            t_ns = seconds_to_ns(t)
            if block and t_ns - block_start >= 1_000_000:
                flush()
                block = []
            if not block:
                block_start = t_ns
            block.append(dvs["dvs_msgs/Event"](x=int(x), y=int(y), ts=ros_time(t_ns),
                                               polarity=p == "1"))
    if block:
        flush()
    first = min(t for t, topic, _ in messages if topic != "/dvs/camera_info")
    with rosbag.Bag(out, "w", compression="lz4") as bag:
        for t_ns, topic, message in sorted(messages, key=lambda item: item[0]):
            if callable(message):
                message = message(first)
                t_ns = first
            bag.write(topic, message, t=ros_time(max(t_ns, first)))


def main():
    if sys.argv[1] == "--from-dataset":
        offset_s = int(sys.argv[4]) if len(sys.argv) > 4 else 0
        write_dataset_bag(sys.argv[2], sys.argv[3], offset_s * 1_000_000_000)
        return
    if sys.argv[1] == "--bench":
        write_bench_bags(int(sys.argv[2]), sys.argv[3])
        return
    small = sys.argv[1] == "--small"
    out = sys.argv[2] if small else sys.argv[1]
    limit = (lambda count, most: min(count, most)) if small else (lambda count, most: count)
    rng = random.Random(15)
    dvs = classes("dvs_msgs/EventArray")
    pro = classes("prophesee_event_msgs/EventArray")
    pkt = classes("event_camera_msgs/EventPacket")
    img = classes("sensor_msgs/Image")
    cam = classes("sensor_msgs/CameraInfo")
    pose = classes("geometry_msgs/PoseStamped")
    messages = []  # (t_ns, topic, message)
    expected = {name: [] for name in ("dvs", "prophesee", "mono", "evt3", "poses", "images")}

    t = T0_NS
    for m in range(limit(12, 2)):
        events = []
        for _ in range(limit(rng.randint(0 if m == 3 else 1, 400), 8)):
            t += rng.randint(0, 20000)
            x, y, p = rng.randrange(240), rng.randrange(180), rng.random() < 0.5
            events.append(dvs["dvs_msgs/Event"](x=x, y=y, ts=ros_time(t), polarity=p))
            expected["dvs"].append("%d %d %d %d" % (t, x, y, 1 if p else -1))
        messages.append((t, "/dvs/events", dvs["dvs_msgs/EventArray"](
            header=header(dvs, m, t), height=180, width=240, events=events)))

    t = T0_NS + 5_000_000
    for m in range(limit(5, 2)):
        events = []
        for _ in range(limit(rng.randint(1, 300), 8)):
            t += rng.randint(1, 3000)
            x, y, p = rng.randrange(640), rng.randrange(480), rng.random() < 0.5
            events.append(pro["prophesee_event_msgs/Event"](x=x, y=y, ts=ros_time(t), polarity=p))
            expected["prophesee"].append("%d %d %d %d" % (t, x, y, 1 if p else -1))
        messages.append((t, "/prophesee/events", pro["prophesee_event_msgs/EventArray"](
            header=header(pro, m, t), height=480, width=640, events=events)))

    t_us = 3_000_000
    for m in range(limit(6, 2)):
        stamp = T0_NS + 10_000_000 * (m + 1)
        words = b""
        evt3 = []
        for _ in range(limit(rng.randint(1, 200), 8)):
            dt = rng.randrange(1 << 20)
            x, y, p = rng.randrange(1280), rng.randrange(720), rng.random() < 0.5
            words += struct.pack("<Q", (int(p) << 63) | (y << 48) | (x << 32) | dt)
            expected["mono"].append("%d %d %d %d" % (stamp + dt, x, y, 1 if p else -1))
            t_us += rng.randint(0, 700)
            evt3.append((t_us, x, y, p))
            expected["evt3"].append("%d %d %d %d" % (t_us * 1000, x, y, 1 if p else -1))
        for encoding, data in (("mono", words), ("evt3", evt3_words(evt3))):
            messages.append((stamp, "/packets/" + encoding, pkt["event_camera_msgs/EventPacket"](
                header=header(pkt, m, stamp), height=720, width=1280, seq=m, time_base=0,
                encoding=encoding, is_bigendian=False, events=data)))

    for m in range(limit(4, 0)):
        stamp = T0_NS + 25_000_000 * m + 1234
        data = bytes(rng.randrange(256) for _ in range(240 * 180))
        messages.append((stamp, "/dvs/image_raw", img["sensor_msgs/Image"](
            header=header(img, m, stamp), height=180, width=240, encoding="mono8",
            is_bigendian=0, step=240, data=data)))
        expected["images"].append("%d 240 180 mono8 %d" % (stamp, sum(data)))

    info = cam["sensor_msgs/CameraInfo"](
        header=header(cam, 0, T0_NS), height=180, width=240, distortion_model="plumb_bob",
        D=[-0.368436311798, 0.150947243557, -0.000296130534385, -0.000759431726241, 0.0],
        K=[199.092366542, 0.0, 132.192071378, 0.0, 198.82882047, 110.712660011, 0.0, 0.0, 1.0],
        R=[1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0], P=[199.0, 0, 132.0, 0, 0, 198.8, 110.7, 0, 0, 0, 1, 0],
        binning_x=0, binning_y=0, roi=cam["sensor_msgs/RegionOfInterest"]())
    messages.append((T0_NS, "/dvs/camera_info", info))

    for m in range(limit(30, 2)):
        stamp = T0_NS + 4_000_000 * m + 17
        x, y, z = 0.1 * m, -0.05 * m, 1.0 + 0.01 * m
        qx, qy, qz, qw = 0.0, 0.0, 0.0998334166, 0.9950041653  # 0.2 rad about z
        messages.append((stamp, "/optitrack/davis", pose["geometry_msgs/PoseStamped"](
            header=header(pose, m, stamp), pose=pose["geometry_msgs/Pose"](
                position=pose["geometry_msgs/Point"](x=x, y=y, z=z),
                orientation=pose["geometry_msgs/Quaternion"](x=qx, y=qy, z=qz, w=qw)))))
        expected["poses"].append("%d %r %r %r %r %r %r %r" % (stamp, x, y, z, qx, qy, qz, qw))

    messages.sort(key=lambda item: item[0])
    for compression in ("none", "bz2", "lz4"):
        # Small chunks, so that every bag has many.
        with rosbag.Bag("%s/test_%s.bag" % (out, compression), "w", compression=compression,
                        chunk_threshold=8192) as bag:
            for t_ns, topic, message in messages:
                bag.write(topic, message, t=ros_time(t_ns))
    for name, lines in expected.items():
        with open("%s/expected_%s.txt" % (out, name), "w") as handle:
            handle.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
