#!/usr/bin/python3
"""The evloc ROS node end to end (docs/ros.md), run by ctest as evloc_ros_node_test.

1. evloc-sim renders a short DAVIS240 sequence with its exact map; core/events/testing/
   write_test_bags.py writes it as a bag with Debian's python3-rosbag (dvs_msgs/EventArray in
   messages of 1 ms, sensor_msgs/CameraInfo, geometry_msgs/PoseStamped ground truth), its times
   moved to 1700000000 s (rosbag play refuses a record time of 0, where the simulation starts).
2. evloc-track tracks the bag from the first ground-truth pose: the reference.
3. A roscore on a free loopback port; ros/launch/evloc.launch starts the node (found through
   ROS_PACKAGE_PATH=<build>/ros/package) at the same pose, twice: tracking in-process, then
   streaming to an evloc-localizer on loopback (server:=, map_name:=); this script listens to
   /dvs/events, /evloc/pose, /evloc/status and /tf; `rosbag play` plays the bag in real time.
4. Checks, for each run: the published poses are evloc-track's, line for line in TUM text
   (bit-identical doubles); every TRACKING pose has its TF map -> camera; the statuses are
   TRACKING.
5. Measures the end-to-end latency from an events message (as this listener receives it) to the
   pose it made due (as this listener receives it), and prints it.

Exit 77 (ctest: skipped, with the reason printed) when Debian's ROS 1 packages are missing
(scripts/install-deps.sh installs them). --out DIR keeps the figures: latency.json, poses.txt,
and trajectory.png (node, evloc-track and ground truth seen from above), the picture of
docs/ros.md.
"""

import argparse
import json
import os
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time


# The bag's times: the simulated dataset's (from 0) moved to a realistic epoch.
BAG_OFFSET_S = 1700000000


def skip(reason):
    print("SKIPPED: " + reason + " (run scripts/install-deps.sh)")
    sys.exit(77)


try:
    import rosbag
    import rosgraph
    import rospy
    from geometry_msgs.msg import PoseWithCovarianceStamped
except ImportError as error:
    skip("/usr/bin/python3 lacks ROS 1's Python packages: %s" % error)
for tool in ("roscore", "roslaunch", "rosbag"):
    if shutil.which(tool) is None:
        skip("%s is not installed" % tool)


def run(command, **kwargs):
    result = subprocess.run(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            **kwargs)
    if result.returncode != 0:
        sys.exit("FAILED: %s exited %d:\n%s" % (" ".join(command), result.returncode,
                                                 result.stdout[-4000:]))
    return result.stdout


def free_port():
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def seconds_text(t_ns):
    return "%d.%09d" % (t_ns // 1_000_000_000, t_ns % 1_000_000_000)


def tum_line(t_ns, values):
    # evloc's TUM writer: exact nanoseconds, shortest round-trip doubles (Python's repr).
    return seconds_text(t_ns) + "".join(" " + repr(float(v)) for v in values)


def last_event_ns(data):
    """The last event's time of a serialized dvs_msgs/EventArray (None when it has none)."""
    frame_id_length = struct.unpack_from("<I", data, 12)[0]
    offset = 16 + frame_id_length + 8
    count = struct.unpack_from("<I", data, offset)[0]
    if count == 0:
        return None
    seconds, nanoseconds = struct.unpack_from("<II", data, offset + 4 + 13 * (count - 1) + 4)
    return seconds * 1_000_000_000 + nanoseconds


def percentile(values, fraction):
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(round(fraction * (len(ordered) - 1))))]


def stop(process, name):
    """Ends a process this script started (its own process group), politely first."""
    if process is None or process.poll() is not None:
        return
    try:
        os.killpg(process.pid, signal.SIGINT)
        process.wait(timeout=15)
    except (subprocess.TimeoutExpired, ProcessLookupError):
        try:
            os.killpg(process.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        process.wait()
    print("stopped %s" % name)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--build", required=True)
    parser.add_argument("--source", required=True)
    parser.add_argument("--out", help="folder for latency.json, poses.txt and trajectory.png")
    parser.add_argument("--duration", default="1.0", help="seconds of the rendered sequence")
    parser.add_argument("--mode", choices=("inprocess", "service", "both"), default="both",
                        help="the node tracking in-process, streaming to a localizer server, or "
                        "one run of each")
    parser.add_argument("--play-rate", default="1.0",
                        help="rosbag play's rate (1: real time; the latency of docs/ros.md)")
    args = parser.parse_args()
    build, source = os.path.abspath(args.build), os.path.abspath(args.source)
    for tool in ("ros/package/evloc_ros/evloc_ros_node", "localizer/service/evloc-localizer",
                 "localizer/offline/evloc-track", "tools/sim/evloc-sim"):
        if not os.access(os.path.join(build, tool), os.X_OK):
            sys.exit("FAILED: %s is not built (cmake --build %s)" % (tool, build))

    work = tempfile.mkdtemp(prefix="evloc-ros-node-")
    roscore = launch = player = server = None
    try:
        dataset = os.path.join(work, "dataset")
        started = time.monotonic()
        run([os.path.join(build, "tools/sim/evloc-sim"), "render", "--out", dataset, "--camera",
             "davis240", "--motion", "slow", "--duration", args.duration, "--seed", "3",
             "--events-txt"])
        bag_path = os.path.join(work, "sequence.bag")
        run(["/usr/bin/python3", os.path.join(source, "core/events/testing/write_test_bags.py"),
             "--from-dataset", dataset, bag_path, str(BAG_OFFSET_S)])
        print("rendered and bagged in %.1f s" % (time.monotonic() - started))

        # The first ground-truth pose, as the bag holds it: the start of both runs.
        with rosbag.Bag(bag_path) as bag:
            _, first, _ = next(bag.read_messages(topics=["/optitrack/davis"]))
        stamp_ns = first.header.stamp.to_nsec()
        p, q = first.pose.position, first.pose.orientation
        init_pose = " ".join(repr(v) for v in (p.x, p.y, p.z, q.x, q.y, q.z, q.w))
        track_out = os.path.join(work, "track.txt")
        track_started = time.monotonic()
        run([os.path.join(build, "localizer/offline/evloc-track"), "--map",
             os.path.join(dataset, "gt_map"), "--dataset", bag_path, "--init-pose", init_pose,
             "--out", track_out, "--quiet"])
        track_wall_s = time.monotonic() - track_started
        with open(track_out) as handle:
            reference = [line.strip() for line in handle if line.strip() and line[0] != "#"]

        port = free_port()
        env = dict(os.environ)
        env.update({
            "ROS_MASTER_URI": "http://127.0.0.1:%d" % port, "ROS_IP": "127.0.0.1",
            "ROS_HOME": os.path.join(work, "ros_home"), "ROS_LOG_DIR": os.path.join(work, "log"),
            "ROS_PACKAGE_PATH": os.path.join(build, "ros/package"),
        })
        os.environ.update(env)
        roscore = subprocess.Popen(["roscore", "-p", str(port)], env=env,
                                   stdout=open(os.path.join(work, "roscore.log"), "w"),
                                   stderr=subprocess.STDOUT, start_new_session=True)
        master = rosgraph.Master("/evloc_ros_node_test")
        deadline = time.monotonic() + 60
        while not master.is_online():
            if time.monotonic() > deadline or roscore.poll() is not None:
                sys.exit("FAILED: roscore did not start on port %d" % port)
            time.sleep(0.2)

        lock = threading.Lock()
        messages, poses, statuses, transforms = [], [], [], []

        def on_events(message):
            arrival = time.monotonic()
            with lock:
                messages.append((arrival, message._buff))

        def on_pose(message):
            arrival = time.monotonic()
            with lock:
                poses.append((arrival, message))

        rospy.init_node("evloc_ros_node_test", anonymous=True, disable_signals=True)
        rospy.Subscriber("/dvs/events", rospy.AnyMsg, on_events, queue_size=100000,
                         tcp_nodelay=True)
        rospy.Subscriber("/evloc/pose", PoseWithCovarianceStamped, on_pose, queue_size=100000,
                         tcp_nodelay=True)
        # evloc_msgs/TrackingStatus has no Python package: decode it with genpy from the
        # definition the node sends in its connection header.
        import genpy.dynamic
        status_classes = {}

        def on_status(message):
            definition = message._connection_header["message_definition"]
            if "class" not in status_classes:
                status_classes["class"] = genpy.dynamic.generate_dynamic(
                    "evloc_msgs/TrackingStatus", definition)["evloc_msgs/TrackingStatus"]
            decoded = status_classes["class"]()
            decoded.deserialize(message._buff)
            with lock:
                statuses.append(decoded)

        rospy.Subscriber("/evloc/status", rospy.AnyMsg, on_status, queue_size=100000)
        from tf2_msgs.msg import TFMessage

        def on_tf(message):
            with lock:
                transforms.extend(message.transforms)

        rospy.Subscriber("/tf", TFMessage, on_tf, queue_size=100000)

        failures = []
        reports = {}
        modes = ["inprocess", "service"] if args.mode == "both" else [args.mode]
        for mode in modes:
            with lock:
                del messages[:], poses[:], statuses[:], transforms[:]
            launch_args = ["init_pose:=" + init_pose, "init_stamp:=" + seconds_text(stamp_ns)]
            if mode == "service":
                # A localizer server on loopback serving the sequence's map as "gt_map".
                maps = os.path.join(work, "maps")
                os.makedirs(maps, exist_ok=True)
                if not os.path.exists(os.path.join(maps, "gt_map")):
                    os.symlink(os.path.join(dataset, "gt_map"), os.path.join(maps, "gt_map"))
                server_port = free_port()
                server = subprocess.Popen(
                    [os.path.join(build, "localizer/service/evloc-localizer"), "serve", "--maps",
                     maps, "--listen", "127.0.0.1:%d" % server_port],
                    stdout=open(os.path.join(work, "server.log"), "w"),
                    stderr=subprocess.STDOUT, start_new_session=True)
                launch_args += ["server:=127.0.0.1:%d" % server_port, "map_name:=gt_map"]
            else:
                launch_args += ["map:=" + os.path.join(dataset, "gt_map")]
            launch = subprocess.Popen(
                ["roslaunch", os.path.join(source, "ros/launch/evloc.launch")] + launch_args,
                env=env, stdout=open(os.path.join(work, "roslaunch.log"), "w"),
                stderr=subprocess.STDOUT, start_new_session=True)
            # Wait until the node subscribes to the events (it has loaded the map).
            deadline = time.monotonic() + 120
            while True:
                _, subscribers, _ = master.getSystemState()
                if "/evloc" in dict(subscribers).get("/dvs/events", []):
                    break
                if time.monotonic() > deadline or launch.poll() is not None:
                    with open(os.path.join(work, "roslaunch.log")) as handle:
                        sys.exit("FAILED (%s): the node did not subscribe to /dvs/events:\n%s" % (
                            mode, handle.read()[-4000:]))
                time.sleep(0.2)
            time.sleep(1.0)
            player = subprocess.Popen(
                ["rosbag", "play", "--quiet", "--wait-for-subscribers", "--rate", args.play_rate,
                 "--topics", "/dvs/events", "/dvs/camera_info", "--", bag_path],
                env=env, stdout=open(os.path.join(work, "play.log"), "w"),
                stderr=subprocess.STDOUT, start_new_session=True)
            if player.wait(timeout=300) != 0:
                with open(os.path.join(work, "play.log")) as handle:
                    sys.exit("FAILED: rosbag play failed:\n" + handle.read()[-4000:])
            # Wait for the last poses (the node or the server may still be working through its
            # queue): until none came for 5 s.
            deadline = time.monotonic() + 120
            count = -1
            while time.monotonic() < deadline:
                time.sleep(5.0)
                with lock:
                    if len(poses) == count:
                        break
                    count = len(poses)
            stop(launch, "roslaunch (%s)" % mode)
            launch = None
            if server is not None:
                stop(server, "evloc-localizer")
                server = None
            with lock:
                poses_seen, messages_seen = list(poses), list(messages)
                statuses_seen, transforms_seen = list(statuses), list(transforms)
            mode_failures, report, published = check_run(
                mode, reference, poses_seen, messages_seen, statuses_seen, transforms_seen)
            report.update({"play_rate": float(args.play_rate),
                           "evloc_track_wall_s": track_wall_s})
            reports[mode] = report
            failures += mode_failures
            if mode_failures:
                for name in ("roslaunch.log", "server.log"):
                    if os.path.exists(os.path.join(work, name)):
                        with open(os.path.join(work, name)) as handle:
                            print("---- %s (end)\n%s" % (name, handle.read()[-3000:]))
            if args.out:
                os.makedirs(args.out, exist_ok=True)
                with open(os.path.join(args.out, "poses_%s.txt" % mode), "w") as handle:
                    handle.write("\n".join(published) + "\n")
                if mode == modes[0]:
                    plot(args.out, published, reference,
                         os.path.join(dataset, "groundtruth.txt"))
        print(json.dumps(reports, indent=2))
        if args.out:
            with open(os.path.join(args.out, "latency.json"), "w") as handle:
                json.dump(reports, handle, indent=2)
        if failures:
            sys.exit("FAILED:\n" + "\n".join(failures))
        print("PASSED: " + "; ".join(
            "%s: %d poses identical to evloc-track's, latency p50 %.2f ms" % (
                mode, report["poses"], report["latency_ms"]["p50"])
            for mode, report in reports.items()))
    finally:
        stop(player, "rosbag play")
        stop(launch, "roslaunch")
        stop(server, "evloc-localizer")
        try:
            rospy.signal_shutdown("done")
        except Exception:
            pass
        stop(roscore, "roscore")
        shutil.rmtree(work, ignore_errors=True)


def check_run(mode, reference, poses_seen, messages_seen, statuses, transforms):
    """The checks and figures of one run of the node."""
    published = [tum_line(m.header.stamp.to_nsec(),
                          (m.pose.pose.position.x, m.pose.pose.position.y,
                           m.pose.pose.position.z, m.pose.pose.orientation.x,
                           m.pose.pose.orientation.y, m.pose.pose.orientation.z,
                           m.pose.pose.orientation.w)) for _, m in poses_seen]
    failures = []
    if len(reference) < 100:
        failures.append("evloc-track gave only %d poses" % len(reference))
    if published != reference:
        mismatch = next((i for i, (a, b) in enumerate(zip(published, reference)) if a != b),
                        min(len(published), len(reference)))
        failures.append(
            "%s: the node published %d poses, evloc-track wrote %d; first difference at %d:\n"
            "  node:        %s\n  evloc-track: %s" % (
                mode, len(published), len(reference), mismatch,
                published[mismatch] if mismatch < len(published) else "(none)",
                reference[mismatch] if mismatch < len(reference) else "(none)"))
    step_statuses = [s.status for s in statuses if s.status != "WAITING"]
    tracking = step_statuses.count("TRACKING")
    camera_transforms = [t for t in transforms
                         if t.header.frame_id == "map" and t.child_frame_id == "camera"]
    if len(camera_transforms) != tracking:
        failures.append("%s: %d TF transforms map -> camera for %d TRACKING poses" % (
            mode, len(camera_transforms), tracking))
    if len(step_statuses) != len(published) or set(step_statuses) != {"TRACKING"}:
        failures.append("%s: %d step statuses (%s) for %d poses" % (
            mode, len(step_statuses), ", ".join(sorted(set(step_statuses))), len(published)))

    # Latency: each pose against the events message that made it due (the first whose last
    # event is after the pose's time), both as this listener received them.
    arrivals = []
    for arrival, data in messages_seen:
        last = last_event_ns(data)
        if last is not None:
            arrivals.append((last, arrival))
    latencies = []
    index = 0
    for arrival, message in poses_seen:
        t_ns = message.header.stamp.to_nsec()
        while index < len(arrivals) and arrivals[index][0] <= t_ns:
            index += 1
        if index < len(arrivals):
            latencies.append((arrival - arrivals[index][1]) * 1e3)
    node_latencies = [s.latency_ms for s in statuses
                      if s.status != "WAITING" and s.latency_ms >= 0]
    step_ms = [s.step_ms for s in statuses if s.status != "WAITING"]
    quarter = max(1, len(latencies) // 4)

    def summary(values):
        if not values:
            return None
        return {"p50": percentile(values, 0.5), "p90": percentile(values, 0.9),
                "p99": percentile(values, 0.99), "max": max(values)}

    report = {
        "poses": len(published), "reference_poses": len(reference),
        "events_messages": len(messages_seen), "tf_transforms": len(camera_transforms),
        "latency_ms": summary(latencies),
        "latency_p50_ms_first_quarter": percentile(latencies[:quarter], 0.5)
        if latencies else None,
        "latency_p50_ms_last_quarter": percentile(latencies[-quarter:], 0.5)
        if latencies else None,
        "step_ms": summary(step_ms),
        "node_latency_ms": summary(node_latencies),
    }
    return failures, report, published


def plot(out, published, reference, groundtruth_path):
    """Position over time: the node's poses, evloc-track's and the ground truth."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    def rows(lines):
        return [[float(v) for v in line.split()] for line in lines]

    with open(groundtruth_path) as handle:
        truth = rows(l for l in handle if l.strip() and not l.startswith("#"))
    node, track = rows(published), rows(reference)
    # The bag's times are the dataset's moved by BAG_OFFSET_S.
    t0 = float(BAG_OFFSET_S)
    t0_truth = 0.0
    figure, axes = plt.subplots(3, 1, figsize=(7, 6), dpi=100, sharex=True)
    for axis, column, name in zip(axes, (1, 2, 3), ("x", "y", "z")):
        axis.plot([r[0] - t0_truth for r in truth], [r[column] for r in truth], color="0.6",
                  linewidth=4, label="ground truth")
        axis.plot([r[0] - t0 for r in track], [r[column] for r in track], color="tab:blue",
                  linewidth=2, label="evloc-track")
        axis.plot([r[0] - t0 for r in node], [r[column] for r in node], color="tab:orange",
                  linestyle="--", linewidth=1.5, label="evloc_ros_node (/evloc/pose)")
        axis.set_ylabel(name + " (m)")
    axes[0].set_title("The ROS node's poses and evloc-track's on the same bag")
    axes[0].legend(loc="best", fontsize=8)
    axes[-1].set_xlabel("time (s)")
    figure.tight_layout()
    figure.savefig(os.path.join(out, "trajectory.png"))


if __name__ == "__main__":
    main()
