#!/usr/bin/python3
"""Writes small AEDAT 4.0 files for the AEDAT4 tests (core/events/aedat4_test.cc,
core/dataset/aedat4_dataset_test.cc), independently of evloc's reader: the tables are built with
Debian's python3-flatbuffers (the flatbuffers project's own Python builder, fed the field
numbers and types of core/events/aedat4_schema/*.fbs by hand, not flatc output), the packet
bodies compressed with python3-lz4 (LZ4 frames) and python3-zstandard (Zstd frames), as
iniVation's DV writes them (docs.inivation.com, "AEDAT 4.0").

Usage: write_test_aedat4.py OUT_DIR
       write_test_aedat4.py --small OUT_DIR   (at most 8 events per packet and one 4x3 frame:
       fuzzing seeds of 1-3 KB, test_<compression>.aedat4)
       write_test_aedat4.py --bench EVENTS OUT_DIR [EVENTS_TXT ...]   (for
       bench/events_benchmark.cc, compressions none, lz4 and zstd at level 3, packets of 10,000
       events on stream 0: bench_<compression>.aedat4 with EVENTS events at uniformly random
       DAVIS346 pixels (the worst case for compression), and, when ECD events.txt files are
       given, bench_ecd_<compression>.aedat4 with EVENTS real DAVIS240 events: the files' events
       one after the other, repeated with shifted times until there are EVENTS)
       write_test_aedat4.py --from-dataset DIR OUT.aedat4   (an lz4 file of a dataset folder's
       events.txt, times rounded to microseconds, stream "events" in packets of 1 ms, sized by
       its calib.yaml, and the images of its images.txt as stream "frames", grey or BGR; for
       tests/bag_end_to_end_test.cc)

Writes, for each compression none / lz4 / lz4-high / zstd / zstd-high,
OUT_DIR/test_<compression>.aedat4 with the streams
  0 events    EVTS 346x260 (a few events beyond 346 or 260 or negative, which readers drop)
  1 frames    FRME 346x260 gray (and one BGR frame)
  2 imu       IMUS
  3 triggers  TRIG
and a data table at the end; OUT_DIR/test_no_table.aedat4 (lz4, data table position -1: a
recording that was never closed); and text files with what was written: expected_events.txt
(`t_ns x y p` of the events inside the sensor), expected_dropped.txt, expected_frames.txt
(`t_ns width height channels sum`), expected_imu.txt (`t_ns temperature ax ay az gx gy gz mx my
mz`), expected_triggers.txt (`t_ns type`).
"""

import os
import random
import struct
import sys

import flatbuffers
import lz4.frame
import numpy
import zstandard

MAGIC = b"#!AER-DAT4.0\r\n"
COMPRESSIONS = {"none": 0, "lz4": 1, "lz4-high": 2, "zstd": 3, "zstd-high": 4}
EVENT_DTYPE = numpy.dtype(
    [("t", "<i8"), ("x", "<i2"), ("y", "<i2"), ("on", "u1"), ("pad", "V3")]
)


def description(streams):
    """DV's outInfo XML: streams is a list of (id, name, type, size or None)."""
    lines = ['<dv version="2.0">', '    <node name="outInfo" path="/mainloop/Recorder/outInfo/">']
    for stream_id, name, type_id, size in streams:
        path = "/mainloop/Recorder/outInfo/%d/" % stream_id
        lines.append('        <node name="%d" path="%s">' % (stream_id, path))
        lines.append('            <attr key="compression" type="string">LZ4</attr>')
        lines.append('            <attr key="originalModuleName" type="string">capture</attr>')
        lines.append('            <attr key="originalOutputName" type="string">%s</attr>' % name)
        lines.append('            <attr key="typeDescription" type="string">&lt;%s&gt; &amp; co</attr>' % name)
        lines.append('            <attr key="typeIdentifier" type="string">%s</attr>' % type_id)
        if size is not None:
            lines.append('            <node name="info" path="%sinfo/">' % path)
            lines.append('                <attr key="sizeX" type="int">%d</attr>' % size[0])
            lines.append('                <attr key="sizeY" type="int">%d</attr>' % size[1])
            lines.append('                <attr key="source" type="string">DAVIS346_00000499</attr>')
            lines.append("            </node>")
        lines.append("        </node>")
    lines.append("    </node>")
    lines.append("</dv>")
    return "\n".join(lines) + "\n"


def io_header(compression, table_position, info):
    builder = flatbuffers.Builder(1024)
    builder.ForceDefaults(True)  # same size whatever the position: rewritten in place
    text = builder.CreateString(info)
    builder.StartObject(3)
    builder.PrependInt32Slot(0, compression, 0)
    builder.PrependInt64Slot(1, table_position, -1)
    builder.PrependUOffsetTRelativeSlot(2, text, 0)
    builder.FinishSizePrefixed(builder.EndObject(), b"IOHE")
    return bytes(builder.Output())


def struct_vector(builder, data, element_size, count):
    """A vector of structs from their packed bytes (element 0 first)."""
    builder.StartVector(element_size, count, 8)
    builder.head = builder.head - len(data)
    builder.Bytes[builder.head : builder.head + len(data)] = data
    return builder.EndVector()


def finish_packet_of_tables(builder, offsets, identifier):
    """The root table {elements: [tables]} of a size-prefixed buffer with `identifier`."""
    builder.StartVector(4, len(offsets), 4)
    for offset in reversed(offsets):
        builder.PrependUOffsetTRelative(offset)
    vector = builder.EndVector()
    builder.StartObject(1)
    builder.PrependUOffsetTRelativeSlot(0, vector, 0)
    builder.FinishSizePrefixed(builder.EndObject(), identifier)
    return bytes(builder.Output())


def event_packet(events):
    """events: numpy array of EVENT_DTYPE."""
    builder = flatbuffers.Builder(len(events) * 16 + 64)
    vector = struct_vector(builder, events.tobytes(), 16, len(events))
    builder.StartObject(1)
    builder.PrependUOffsetTRelativeSlot(0, vector, 0)
    builder.FinishSizePrefixed(builder.EndObject(), b"EVTS")
    return bytes(builder.Output())


def frame_packet(t_us, width, height, fmt, pixels):
    builder = flatbuffers.Builder(len(pixels) + 128)
    data = builder.CreateByteVector(pixels)
    builder.StartObject(11)
    builder.PrependInt64Slot(0, t_us, 0)
    builder.PrependInt64Slot(1, t_us - 100, 0)
    builder.PrependInt64Slot(2, t_us + 900, 0)
    builder.PrependInt64Slot(3, t_us, 0)
    builder.PrependInt64Slot(4, t_us + 500, 0)
    builder.PrependInt8Slot(5, fmt, 0)
    builder.PrependInt16Slot(6, width, 0)
    builder.PrependInt16Slot(7, height, 0)
    builder.PrependInt16Slot(8, 0, 0)
    builder.PrependInt16Slot(9, 0, 0)
    builder.PrependUOffsetTRelativeSlot(10, data, 0)
    builder.FinishSizePrefixed(builder.EndObject(), b"FRME")
    return bytes(builder.Output())


def imu_packet(samples):
    builder = flatbuffers.Builder(1024)
    offsets = []
    for sample in samples:
        builder.StartObject(11)
        builder.PrependInt64Slot(0, sample[0], 0)
        for slot, value in enumerate(sample[1:], start=1):
            builder.PrependFloat32Slot(slot, value, 0.0)
        offsets.append(builder.EndObject())
    return finish_packet_of_tables(builder, offsets, b"IMUS")


def trigger_packet(triggers):
    builder = flatbuffers.Builder(256)
    offsets = []
    for t_us, kind in triggers:
        builder.StartObject(2)
        builder.PrependInt64Slot(0, t_us, 0)
        builder.PrependInt8Slot(1, kind, 0)
        offsets.append(builder.EndObject())
    return finish_packet_of_tables(builder, offsets, b"TRIG")


def data_table(entries):
    """DV's FileDataTable: [FileDataDefinition{ByteOffset, PacketInfo{StreamID, Size},
    NumElements, TimestampStart, TimestampEnd}]."""
    builder = flatbuffers.Builder(1024)
    offsets = []
    for offset, stream_id, size, count, start, end in entries:
        builder.StartObject(5)
        builder.PrependInt64Slot(0, offset, 0)
        builder.Prep(4, 8)
        builder.PrependInt32(size)
        builder.PrependInt32(stream_id)
        builder.Slot(1)
        builder.PrependInt64Slot(2, count, 0)
        builder.PrependInt64Slot(3, start, 0)
        builder.PrependInt64Slot(4, end, 0)
        offsets.append(builder.EndObject())
    return finish_packet_of_tables(builder, offsets, b"FTAB")


def compress(body, compression):
    if compression == "none":
        return body
    if compression == "lz4":
        return lz4.frame.compress(body, compression_level=0)
    if compression == "lz4-high":
        return lz4.frame.compress(body, compression_level=lz4.frame.COMPRESSIONLEVEL_MINHC)
    if compression == "zstd":
        # The frame states its decompressed size, as DV's one-shot compression writes it.
        return zstandard.ZstdCompressor(level=3).compress(body)
    # No content size in the frame header: the reader must grow its buffer.
    return zstandard.ZstdCompressor(level=19, write_content_size=False).compress(body)


def write_file(path, compression, streams, packets, with_table=True):
    """packets: list of (stream_id, body, count, t_start_us, t_end_us)."""
    info = description(streams)
    header = io_header(COMPRESSIONS[compression], -1, info)
    out = bytearray(MAGIC + header)
    entries = []
    for stream_id, body, count, start, end in packets:
        data = compress(body, compression)
        entries.append((len(out), stream_id, len(data), count, start, end))
        out += struct.pack("<ii", stream_id, len(data)) + data
    if with_table:
        position = len(out)
        out += compress(data_table(entries), compression)
        final = io_header(COMPRESSIONS[compression], position, info)
        assert len(final) == len(header)
        out[len(MAGIC) : len(MAGIC) + len(header)] = final
    tmp = path + ".tmp"
    with open(tmp, "wb") as handle:
        handle.write(out)
    os.replace(tmp, path)


def make_events(rng, count, t0_us, width, height, outside):
    events = numpy.zeros(count, dtype=EVENT_DTYPE)
    t = t0_us
    for i in range(count):
        t += rng.randint(0, 40)
        events[i]["t"] = t
        events[i]["x"] = rng.randrange(width)
        events[i]["y"] = rng.randrange(height)
        events[i]["on"] = rng.randrange(2)
    for i in outside:
        events[i]["x"] = [width, -1, 5][i % 3]
        events[i]["y"] = [0, 7, height][i % 3]
    return events


def write_test_files(out_dir, small):
    rng = random.Random(15)
    width, height = 346, 260
    streams = [
        (0, "events", "EVTS", (width, height)),
        (1, "frames", "FRME", (width, height)),
        (2, "imu", "IMUS", None),
        (3, "triggers", "TRIG", None),
    ]
    packets = []
    expected_events, expected_frames, expected_imu, expected_triggers = [], [], [], []
    dropped = 0
    t_us = 1_700_000_000_000_000  # a DV clock: microseconds since 1970
    per_packet = 8 if small else 3000
    for packet_index in range(2 if small else 4):
        outside = [1, 4, 6] if packet_index == 0 else []
        events = make_events(rng, per_packet, t_us, width, height, outside)
        t_us = int(events[-1]["t"]) + 1
        packets.append((0, event_packet(events), len(events), int(events[0]["t"]), t_us - 1))
        for event in events:
            x, y = int(event["x"]), int(event["y"])
            if 0 <= x < width and 0 <= y < height:
                expected_events.append("%d %d %d %d" % (int(event["t"]) * 1000, x, y,
                                                        1 if event["on"] else -1))
            else:
                dropped += 1
        # A frame, IMU samples and a trigger after every events packet.
        fw, fh = (4, 3) if small else (width, height)
        channels = 3 if packet_index == 1 else 1
        pixels = bytes(rng.randrange(256) for _ in range(fw * fh * channels))
        packets.append((1, frame_packet(t_us, fw, fh, 16 if channels == 3 else 0, pixels), 1,
                        t_us, t_us))
        expected_frames.append("%d %d %d %d %d" % (t_us * 1000, fw, fh, channels, sum(pixels)))
        samples = []
        for k in range(2 if small else 5):
            sample = [t_us + 1000 * k, 35.5] + [rng.uniform(-2, 2) for _ in range(9)]
            sample[1:] = [struct.unpack("<f", struct.pack("<f", v))[0] for v in sample[1:]]
            samples.append(sample)
            expected_imu.append(" ".join([str(sample[0] * 1000)] + ["%.9g" % v for v in sample[1:]]))
        packets.append((2, imu_packet(samples), len(samples), samples[0][0], samples[-1][0]))
        trigger = (t_us + 3, packet_index % 10)
        packets.append((3, trigger_packet([trigger]), 1, trigger[0], trigger[0]))
        expected_triggers.append("%d %d" % (trigger[0] * 1000, trigger[1]))
        t_us += 5000
    for compression in COMPRESSIONS:
        write_file(os.path.join(out_dir, "test_%s.aedat4" % compression), compression, streams,
                   packets)
    write_file(os.path.join(out_dir, "test_no_table.aedat4"), "lz4", streams, packets,
               with_table=False)
    for name, lines in (("events", expected_events), ("frames", expected_frames),
                        ("imu", expected_imu), ("triggers", expected_triggers),
                        ("dropped", [str(dropped)])):
        with open(os.path.join(out_dir, "expected_%s.txt" % name), "w") as handle:
            handle.write("\n".join(lines) + "\n")


def write_bench_set(events, size, out_dir, prefix):
    per_packet = 10000
    packets = []
    for start in range(0, len(events), per_packet):
        chunk = events[start : start + per_packet]
        packets.append((0, event_packet(chunk), len(chunk), int(chunk[0]["t"]), int(chunk[-1]["t"])))
    streams = [(0, "events", "EVTS", size)]
    for compression in ("none", "lz4", "zstd"):
        write_file(os.path.join(out_dir, "%s_%s.aedat4" % (prefix, compression)), compression,
                   streams, packets)


def write_bench_files(count, out_dir, events_txt):
    rng = numpy.random.default_rng(15)
    width, height = 346, 260
    events = numpy.zeros(count, dtype=EVENT_DTYPE)
    events["t"] = 1_000_000 + numpy.cumsum(rng.integers(0, 3, count))
    events["x"] = rng.integers(0, width, count)
    events["y"] = rng.integers(0, height, count)
    events["on"] = rng.integers(0, 2, count)
    write_bench_set(events, (width, height), out_dir, "bench")
    if not events_txt:
        return
    pieces = []
    for path in events_txt:
        data = numpy.loadtxt(path, ndmin=2)
        piece = numpy.zeros(len(data), dtype=EVENT_DTYPE)
        piece["t"] = numpy.rint(data[:, 0] * 1e6).astype(numpy.int64)
        piece["t"] -= piece["t"][0]
        piece["x"], piece["y"], piece["on"] = data[:, 1], data[:, 2], data[:, 3] > 0
        pieces.append(piece)
    real = numpy.zeros(count, dtype=EVENT_DTYPE)
    filled, offset = 0, 1_000_000
    while filled < count:
        for piece in pieces:
            take = min(len(piece), count - filled)
            real[filled : filled + take] = piece[:take]
            real["t"][filled : filled + take] += offset
            offset = int(real["t"][filled + take - 1]) + 1
            filled += take
            if filled == count:
                break
    write_bench_set(real, (240, 180), out_dir, "bench_ecd")


def write_from_dataset(folder, out_path):
    """The events.txt (t_s x y p) of a dataset folder, sized by its calib.yaml, and the images of
    its images.txt as a frames stream (times rounded to microseconds)."""
    import yaml  # python3-yaml, only for this mode

    data = numpy.loadtxt(os.path.join(folder, "events.txt"), ndmin=2)
    events = numpy.zeros(len(data), dtype=EVENT_DTYPE)
    events["t"] = numpy.rint(data[:, 0] * 1e6).astype(numpy.int64)
    events["x"] = data[:, 1]
    events["y"] = data[:, 2]
    events["on"] = data[:, 3] > 0
    with open(os.path.join(folder, "calib.yaml")) as handle:
        calib = yaml.safe_load(handle)
    width, height = int(calib["width"]), int(calib["height"])
    edges = numpy.searchsorted(events["t"], numpy.arange(events["t"][0], events["t"][-1] + 1001, 1000))
    packets = []
    for begin, end in zip(edges[:-1], edges[1:]):
        if end > begin:
            chunk = events[begin:end]
            packets.append((0, event_packet(chunk), len(chunk), int(chunk[0]["t"]), int(chunk[-1]["t"])))
    streams = [(0, "events", "EVTS", (width, height))]
    images_txt = os.path.join(folder, "images.txt")
    if os.path.exists(images_txt):
        # The images as the frames stream: grey, or BGR (format 16) from an RGB PNG.
        from PIL import Image  # python3-pil, only for this mode
        streams.append((1, "frames", "FRME", (width, height)))
        with open(images_txt) as handle:
            for line in handle:
                if not line.strip() or line.startswith("#"):
                    continue
                t, path = line.split()[:2]
                t_us = int(round(float(t) * 1e6))
                picture = Image.open(os.path.join(folder, path))
                pixels = numpy.asarray(picture)
                if picture.mode == "RGB":
                    pixels, fmt = pixels[:, :, ::-1], 16
                else:
                    fmt = 0
                packets.append((1, frame_packet(t_us, picture.width, picture.height, fmt,
                                                numpy.ascontiguousarray(pixels).tobytes()),
                                1, t_us, t_us))
        packets.sort(key=lambda packet: packet[3])
    write_file(out_path, "lz4", streams, packets)


def main(argv):
    if len(argv) == 3 and argv[1] == "--small":
        os.makedirs(argv[2], exist_ok=True)
        write_test_files(argv[2], small=True)
    elif len(argv) >= 4 and argv[1] == "--bench":
        os.makedirs(argv[3], exist_ok=True)
        write_bench_files(int(argv[2]), argv[3], argv[4:])
    elif len(argv) == 4 and argv[1] == "--from-dataset":
        write_from_dataset(argv[2], argv[3])
    elif len(argv) == 2:
        os.makedirs(argv[1], exist_ok=True)
        write_test_files(argv[1], small=False)
    else:
        sys.stderr.write(__doc__)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
