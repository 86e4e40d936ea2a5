#!/usr/bin/env python3
"""A hand-held path that looks away from the mapped part of the room and comes back (issue 17,
docs/accuracy.md "Hand-over"): TUM poses (world_from_cam) relative to the first one, which
`evloc-sim render --trajectory` anchors at the room's default viewpoint.

  0 .. T0           on the map: small hand-held motion in front of the mapped view
  T0 .. T0+TURN     turns by YAW degrees about the camera's vertical axis (away from the map)
  .. +AWAY          away: hand-held motion (sideways sway, small rotations)
  .. +TURN          turns back
  .. end (+T1)      on the map again

Render it with `--map-until T0` so that the map holds only what the first T0 seconds saw.
Deterministic: no random numbers.

Usage: handover_path.py OUT.txt [--on 1.5] [--turn 1.0] [--away 5.0] [--back 1.5] [--yaw 90]
"""
import argparse
import math


def smoothstep(x):
    """0 before 0, 1 after 1, C1 in between."""
    x = min(max(x, 0.0), 1.0)
    return x * x * (3 - 2 * x)


def quaternion_from_rotation_vector(rx, ry, rz):
    angle = math.sqrt(rx * rx + ry * ry + rz * rz)
    if angle < 1e-12:
        return (0.0, 0.0, 0.0, 1.0)
    s = math.sin(angle / 2) / angle
    return (rx * s, ry * s, rz * s, math.cos(angle / 2))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out")
    parser.add_argument("--on", type=float, default=1.5, help="seconds on the map first")
    parser.add_argument("--turn", type=float, default=1.0, help="seconds of each turn")
    parser.add_argument("--away", type=float, default=5.0, help="seconds away from the map")
    parser.add_argument("--back", type=float, default=1.5, help="seconds on the map at the end")
    parser.add_argument("--yaw", type=float, default=90.0, help="turn, degrees")
    parser.add_argument("--rate", type=float, default=200.0, help="poses per second")
    args = parser.parse_args()
    total = args.on + 2 * args.turn + args.away + args.back
    yaw = math.radians(args.yaw)
    lines = []
    n = int(round(total * args.rate))
    for i in range(n + 1):
        t = i / args.rate
        # Yaw about the camera's y axis (down in the camera: the room's vertical), out and back.
        out = smoothstep((t - args.on) / args.turn)
        back = smoothstep((t - args.on - args.turn - args.away) / args.turn)
        psi = yaw * (out - back)
        # Hand-held sway: a few centimetres sideways and forward, small tilts.
        x = 0.06 * math.sin(2 * math.pi * 0.35 * t) + 0.02 * math.sin(2 * math.pi * 1.1 * t)
        y = 0.015 * math.sin(2 * math.pi * 0.8 * t + 0.5)
        z = 0.04 * math.sin(2 * math.pi * 0.23 * t + 1.0)
        pitch = math.radians(2.0) * math.sin(2 * math.pi * 0.5 * t)
        roll = math.radians(1.5) * math.sin(2 * math.pi * 0.7 * t + 0.3)
        # world_from_cam = translate(x, y, z) * R_y(psi) * R_x(pitch) * R_z(roll), composed as
        # rotation vectors (small tilts: the yaw dominates).
        qy = quaternion_from_rotation_vector(0.0, psi, 0.0)
        qx = quaternion_from_rotation_vector(pitch, 0.0, 0.0)
        qz = quaternion_from_rotation_vector(0.0, 0.0, roll)
        q = multiply(multiply(qy, qx), qz)
        lines.append(f"{t:.6f} {x:.9f} {y:.9f} {z:.9f} {q[0]:.12f} {q[1]:.12f} {q[2]:.12f} {q[3]:.12f}")
    with open(args.out, "w", encoding="ascii") as handle:
        handle.write("# evloc handover path: on %.3f s, turn %.3f s, away %.3f s, back %.3f s, "
                     "yaw %.1f deg\n" % (args.on, args.turn, args.away, args.back, args.yaw))
        handle.write("\n".join(lines) + "\n")


def multiply(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz)


if __name__ == "__main__":
    main()
