#!/usr/bin/env python3
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

It uses the evloc package (python/, docs/python.md: `make python`, then run it with
.venv/bin/python): evloc.Client and its sessions, which encode the events PACKED with NumPy.

Exit codes: 0 the session ended normally, 1 it failed (the gRPC status is printed), 2 bad usage.
"""

import argparse
import json
import sys

import numpy as np

import evloc


def add_token_arguments(parser):
    """The bearer token flags of the examples: --token-file, and the deprecated --token."""
    parser.add_argument("--token-file",
                        help="file holding the bearer token (one line); preferred to --token")
    parser.add_argument("--token", help="bearer token (visible in the process list: deprecated, "
                        "use --token-file)")


def client_of(parser, args):
    """An evloc.Client for --server with the token of --token-file or --token; a usage error for
    both or for a file that does not hold one token on one line."""
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
    return evloc.Client(args.server, token=token or None)


def read_events(path):
    """Reads `t_ns x y polarity` lines into the (t, x, y, p) arrays evloc takes."""
    table = np.loadtxt(path, dtype=np.int64, ndmin=2)
    return table[:, 0], table[:, 1], table[:, 2], np.where(table[:, 3] > 0, 1, -1)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--server", required=True, help="localizer address, host:port")
    parser.add_argument("--map", required=True, help="map name (ListMaps)")
    parser.add_argument("--session", required=True, help="session JSON (camera, initial pose)")
    parser.add_argument("--events", required=True, help="text events: t_ns x y polarity")
    parser.add_argument("--packet-us", type=int, default=1000, help="packet window, microseconds")
    parser.add_argument("--rate", type=float, default=0, help="tracking steps per second")
    add_token_arguments(parser)
    parser.add_argument("--quiet", action="store_true", help="print only the totals")
    args = parser.parse_args()

    with open(args.session, encoding="utf-8") as file:
        session = json.load(file)
    events = read_events(args.events)
    pose = None
    if "initial_world_from_cam" in session:
        given = session["initial_world_from_cam"]
        qw, qx, qy, qz = given["q"]
        pose = [*given["t"], qx, qy, qz, qw]

    poses = searching = 0
    try:
        with client_of(parser, args) as client, client.session(
                args.map, session["camera"], initial_pose=pose,
                initial_t_ns=session["initial_t_ns"], step_rate_hz=args.rate or None,
                packet_ms=args.packet_us / 1000.0,
                client_name="examples/python/localizer_client.py") as stream:
            started = stream.started
            print(f"session {started.session_id}: map {started.map.name} version "
                  f"{started.map.version}, {started.variant} at {started.step_rate_hz:g} Hz")
            stream.send(events)
            # The end of the stream: the last packet ends where its window ends (windows of
            # packet_us from just before the first event, as the session cuts them).
            window_ns = args.packet_us * 1000
            origin = int(events[0][0]) - 1
            stream.close(end_t_ns=origin - (origin - int(events[0][-1])) // window_ns * window_ns)
            for update in stream.poses():
                if update.pose is None:
                    # INITIALIZING / RELOCALIZING: the service is searching and has no pose.
                    searching += 1
                    if not args.quiet:
                        print(f"update t={update.t_ns * 1e-9:.6f} s  {update.status.name}")
                    continue
                poses += 1
                if not args.quiet:
                    t, q = update.pose[:3], update.pose[3:]
                    print(f"pose t={update.t_ns * 1e-9:.6f} s  t=({t[0]:.4f}, {t[1]:.4f}, "
                          f"{t[2]:.4f}) q=({q[3]:.5f}, {q[0]:.5f}, {q[1]:.5f}, {q[2]:.5f})  "
                          f"{update.status.name}  points {update.quality['points_used']}  "
                          f"latency {update.latency_us:.0f} us")
            end = stream.end
            print(f"end: {end.events} events, {end.poses} poses ({end.lost_poses} LOST), "
                  f"latency p50 {end.latency_p50_us:.0f} us p99 {end.latency_p99_us:.0f} us")
    except evloc.ServiceError as error:
        print(f"session failed: {error}", file=sys.stderr)
        return 1
    print(f"received {poses} poses" +
          (f" after {searching} updates without a pose (searching)" if searching else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
