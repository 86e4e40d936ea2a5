#!/usr/bin/env python3
"""Locates one image in a map through the evloc localizer's Locate RPC (docs/api.md).

A client that does not know where it is (a robot booting in a car park, a tracker that lost the
map) sends one grey or colour image with its camera; the service answers FOUND with a verified
pose and its covariance, or NOT_FOUND, a result and not an error (docs/relocalization.md).
The answer is printed as the JSON object of `evloc-localizer locate --json`. With
--write-session the found pose goes into a session JSON that localizer_client.py starts a Track
session from.

Input:
  --image FILE    a PNG or JPEG image of the camera's size (sent as the file's bytes).
  --camera FILE   JSON with the camera, as in localizer_client.py's session JSON:
                  {"camera": {"model": "pinhole", "width": 640, "height": 480,
                              "fx": 500, "fy": 500, "cx": 319.5, "cy": 239.5,
                              "distortion": []}}

It uses the evloc package (docs/python.md): evloc.Client.locate.

Exit codes: 0 FOUND, 3 NOT_FOUND, 1 the call failed (the gRPC status is printed), 2 bad usage.
"""

import argparse
import json
import os
import sys

import evloc

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from localizer_client import add_token_arguments, client_of  # noqa: E402

EXIT_FOUND, EXIT_FAILED, EXIT_NOT_FOUND = 0, 1, 3


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n", maxsplit=1)[0])
    parser.add_argument("--server", required=True, help="localizer address, host:port")
    parser.add_argument("--map", required=True, help="map name (ListMaps)")
    parser.add_argument("--image", required=True, help="PNG or JPEG image")
    parser.add_argument("--camera", required=True, help="JSON file with the image's camera")
    add_token_arguments(parser)
    parser.add_argument("--timeout", type=float, default=30, help="deadline of the call, seconds")
    parser.add_argument("--write-session", metavar="FILE",
                        help="when FOUND, write a localizer_client.py session JSON at the pose")
    parser.add_argument("--t-ns", type=int, default=0,
                        help="with --write-session: the session time of the image, ns")
    args = parser.parse_args()

    with open(args.camera, encoding="utf-8") as file:
        camera = json.load(file)["camera"]
    with open(args.image, "rb") as file:
        image = file.read()

    try:
        with client_of(parser, args) as client:
            result = client.locate(args.map, camera, image, timeout_s=args.timeout)
    except evloc.ServiceError as error:
        print(f"locate failed: {error}", file=sys.stderr)
        return EXIT_FAILED

    answer = {"status": result.status}
    if result.found:
        answer["world_from_cam"] = [float(v) for v in result.pose]
        answer["covariance"] = [float(v) for v in result.covariance.reshape(-1)]
    answer.update({"inliers": result.inliers, "keyframe": result.keyframe,
                   "score": result.score, "reason": result.reason,
                   "map_version": result.map_version, "locate_ms": result.locate_ms})
    print(json.dumps(answer))
    if result.found and args.write_session:
        t, q = answer["world_from_cam"][:3], answer["world_from_cam"][3:]
        session = {"camera": camera, "initial_t_ns": args.t_ns,
                   "initial_world_from_cam": {"t": t, "q": [q[3], q[0], q[1], q[2]]}}
        partial = args.write_session + ".partial"
        with open(partial, "w", encoding="utf-8") as file:
            json.dump(session, file)
        os.replace(partial, args.write_session)
    return EXIT_FOUND if result.found else EXIT_NOT_FOUND


if __name__ == "__main__":
    sys.exit(main())
