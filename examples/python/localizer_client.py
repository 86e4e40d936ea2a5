#!/usr/bin/python3
"""Minimal Python client of the evloc localizer (docs/api.md).

Streams events to a running `evloc-localizer serve` over the evloc.api.Localizer/Track stream
and prints every pose it gets back, then the session totals.

Input:
  --session FILE  JSON with the camera and the initial pose:
                  {"camera": {"model": "pinhole", "width": 320, "height": 240,
                              "fx": 250, "fy": 250, "cx": 159.5, "cy": 119.5,
                              "distortion": []},
                   "initial_t_ns": 20000000,
                   "initial_world_from_cam": {"t": [x, y, z], "q": [qw, qx, qy, qz]}}
                  Without "initial_world_from_cam" the service finds the camera in the map
                  from the events: its updates say INITIALIZING, without a pose, until then
                  (locate_client.py finds a pose from one image instead).
  --events FILE   text events, one per line: t_ns x y polarity (polarity 1 = ON, 0 or -1 = OFF),
                  in time order.

The Python stubs come from proto/evloc/*.proto: pass --stubs DIR (holding evloc/localizer_pb2.py
and evloc/localizer_pb2_grpc.py), or let the script generate them into a temporary folder with
`protoc` and `grpc_python_plugin` (Debian: protobuf-compiler, protobuf-compiler-grpc).

Exit codes: 0 the session ended normally, 1 it failed (the gRPC status is printed), 2 bad usage.
"""

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import threading

import numpy as np

REPO_ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))


def generate_stubs(proto_root, out_dir, protoc="protoc", plugin=None):
    """Generates the Python modules of evloc/map.proto and evloc/localizer.proto into out_dir."""
    plugin = plugin or shutil.which("grpc_python_plugin") or "/usr/bin/grpc_python_plugin"
    command = [protoc, "-I", proto_root, "--python_out=" + out_dir,
               "--grpc_python_out=" + out_dir,
               "--plugin=protoc-gen-grpc_python=" + plugin,
               "evloc/map.proto", "evloc/localizer.proto"]
    subprocess.run(command, check=True)


def load_stubs(stubs_dir):
    """Imports the generated modules from stubs_dir."""
    sys.path.insert(0, stubs_dir)
    from evloc import localizer_pb2, localizer_pb2_grpc  # pylint: disable=import-outside-toplevel
    return localizer_pb2, localizer_pb2_grpc


def stubs(stubs_dir, protoc):
    """The stub modules (api, api_grpc): imported from stubs_dir, or generated with protoc into a
    temporary folder that is removed once they are imported."""
    if stubs_dir is not None:
        return load_stubs(stubs_dir)
    temporary = tempfile.mkdtemp(prefix="evloc-stubs-")
    try:
        generate_stubs(os.path.join(REPO_ROOT, "proto"), temporary, protoc=protoc)
        return load_stubs(temporary)
    finally:
        shutil.rmtree(temporary, ignore_errors=True)


def fill_camera(camera, message):
    """Fills an evloc.map_format.Camera message from the session JSON's "camera" object."""
    models = {"pinhole": 1, "radtan": 2, "equidistant": 3}
    message.model = models[camera["model"]]
    for key in ("width", "height", "fx", "fy", "cx", "cy"):
        setattr(message, key, camera[key])
    message.distortion.extend(camera.get("distortion", []))


def add_token_arguments(parser):
    """The bearer token flags of the examples: --token-file, and the deprecated --token."""
    parser.add_argument("--token-file",
                        help="file holding the bearer token (one line); preferred to --token")
    parser.add_argument("--token", help="bearer token (visible in the process list: deprecated, "
                        "use --token-file)")


def auth_metadata(parser, args):
    """The call metadata for the token of --token-file or --token (None without one); a usage
    error for both or for a file that does not hold one token on one line."""
    token = args.token
    if args.token and args.token_file:
        parser.error("--token and --token-file exclude each other")
    if args.token:
        print(f"{parser.prog}: warning: --token shows the secret in the process list; "
              "use --token-file", file=sys.stderr)
    if args.token_file:
        with open(args.token_file, encoding="utf-8") as file:
            token = file.read().strip()
        if not token or any(c.isspace() for c in token):
            parser.error(f"--token-file {args.token_file}: expected one token on one line")
    return [("authorization", "Bearer " + token)] if token else None


def read_events(path):
    """Reads `t_ns x y polarity` lines into numpy arrays (t int64, x, y uint16, on bool)."""
    table = np.loadtxt(path, dtype=np.int64, ndmin=2)
    return table[:, 0], table[:, 1].astype(np.uint16), table[:, 2].astype(np.uint16), table[:, 3] > 0


def pack_events(t_ns, x, y, on, time_base_ns):
    """PACKED encoding: 8 bytes per event, little-endian uint32 (t - base) | on << 31, uint16 x,
    uint16 y (docs/api.md)."""
    records = np.empty(len(t_ns), dtype=[("t", "<u4"), ("x", "<u2"), ("y", "<u2")])
    offsets = (t_ns - time_base_ns).astype(np.uint64)
    if len(offsets) and offsets.max() >= 2**31:
        raise ValueError("a packet spans more than 2^31 ns")
    records["t"] = (offsets | (on.astype(np.uint64) << np.uint64(31))).astype(np.uint32)
    records["x"] = x
    records["y"] = y
    return records.tobytes()


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--server", required=True, help="localizer address, host:port")
    parser.add_argument("--map", required=True, help="map name (ListMaps)")
    parser.add_argument("--session", required=True, help="session JSON (camera, initial pose)")
    parser.add_argument("--events", required=True, help="text events: t_ns x y polarity")
    parser.add_argument("--stubs", help="folder with the generated evloc/*_pb2*.py modules")
    parser.add_argument("--protoc", default="protoc", help="protoc used to generate the stubs")
    parser.add_argument("--packet-us", type=int, default=1000, help="packet window, microseconds")
    parser.add_argument("--rate", type=float, default=0, help="tracking steps per second")
    add_token_arguments(parser)
    parser.add_argument("--quiet", action="store_true", help="print only the totals")
    args = parser.parse_args()

    import grpc  # pylint: disable=import-outside-toplevel

    api, api_grpc = stubs(args.stubs, args.protoc)

    with open(args.session, encoding="utf-8") as file:
        session = json.load(file)
    t_ns, x, y, on = read_events(args.events)

    start = api.SessionStart(map_name=args.map, initial_t_ns=session["initial_t_ns"],
                             client_name="examples/python/localizer_client.py")
    fill_camera(session["camera"], start.camera)
    if "initial_world_from_cam" in session:
        pose = session["initial_world_from_cam"]
        start.initial_world_from_cam.translation.x, start.initial_world_from_cam.translation.y, \
            start.initial_world_from_cam.translation.z = pose["t"]
        rotation = start.initial_world_from_cam.rotation
        rotation.w, rotation.x, rotation.y, rotation.z = pose["q"]
    if args.rate > 0:
        start.options.step_rate_hz = args.rate

    # Flow control: at most `max_in_flight` packets not yet confirmed by a pose.
    confirmed = threading.Condition()
    state = {"last_pose_t_ns": session["initial_t_ns"], "done": False}
    max_in_flight = 32

    def requests():
        yield api.TrackRequest(start=start)
        packet_ns = args.packet_us * 1000
        window_start = int(t_ns[0]) - 1
        begin = 0
        sent_ends = []
        while begin < len(t_ns):
            window_end = window_start + packet_ns
            end = int(np.searchsorted(t_ns, window_end, side="right"))
            with confirmed:
                confirmed.wait_for(lambda: state["done"] or sum(
                    1 for e in sent_ends if e > state["last_pose_t_ns"]) < max_in_flight,
                                   timeout=0.02)
            sent_ends = [e for e in sent_ends if e > state["last_pose_t_ns"]] + [window_end]
            yield api.TrackRequest(events=api.EventPacket(
                encoding=api.EVENT_ENCODING_PACKED, time_base_ns=window_start,
                end_t_ns=window_end,
                data=pack_events(t_ns[begin:end], x[begin:end], y[begin:end], on[begin:end],
                                 window_start)))
            begin = end
            window_start = window_end

    channel = grpc.insecure_channel(args.server)
    stub = api_grpc.LocalizerStub(channel)
    metadata = auth_metadata(parser, args)
    poses = 0
    searching = 0
    try:
        for response in stub.Track(requests(), metadata=metadata):
            kind = response.WhichOneof("message")
            if kind == "started":
                print(f"session {response.started.session_id}: map {response.started.map.name} "
                      f"version {response.started.map.version}, {response.started.variant} at "
                      f"{response.started.step_rate_hz:g} Hz")
            elif kind == "pose":
                update = response.pose
                with confirmed:
                    state["last_pose_t_ns"] = update.t_ns
                    confirmed.notify_all()
                status = api.TrackingStatus.Name(update.status)
                if not update.HasField("world_from_cam"):
                    # INITIALIZING / RELOCALIZING: the service is searching and has no pose.
                    searching += 1
                    if not args.quiet:
                        print(f"update t={update.t_ns * 1e-9:.6f} s  {status}")
                    continue
                poses += 1
                if not args.quiet:
                    p = update.world_from_cam
                    print(f"pose t={update.t_ns * 1e-9:.6f} s  t=({p.translation.x:.4f}, "
                          f"{p.translation.y:.4f}, {p.translation.z:.4f}) "
                          f"q=({p.rotation.w:.5f}, {p.rotation.x:.5f}, {p.rotation.y:.5f}, "
                          f"{p.rotation.z:.5f})  {status}  points {update.quality.points_used}  "
                          f"latency {update.latency_us:.0f} us")
            elif kind == "backpressure":
                print(f"backpressure: {response.backpressure.queued_packets} of "
                      f"{response.backpressure.queue_capacity} packets queued")
            elif kind == "end":
                end = response.end
                print(f"end: {end.events} events, {end.poses} poses ({end.lost_poses} LOST), "
                      f"latency p50 {end.latency_p50_us:.0f} us p99 {end.latency_p99_us:.0f} us")
    except grpc.RpcError as error:
        print(f"session failed: {error.code().name}: {error.details()}", file=sys.stderr)
        return 1
    finally:
        with confirmed:
            state["done"] = True
            confirmed.notify_all()
    print(f"received {poses} poses" +
          (f" after {searching} updates without a pose (searching)" if searching else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
