#!/usr/bin/python3
"""The circling path of the mapper's synthetic-room accuracy figures (docs/mapper.md).

Writes a TUM trajectory (world_from_cam, 1 kHz) for `evloc-sim render --trajectory`: the camera
circles the middle of the default room once, at constant angular speed, always looking at one
point above the table, so that it sees the table, its boxes and every wall behind them in turn.

The replay is anchor * first^-1 * pose, with the simulator's anchor at the camera-region centre
looking at the room's centre; the path starts exactly at that anchor (the look-at point lies on
the anchor's optical axis, RADIUS metres away horizontally), so the rendered poses are these.
A vertical wave (AMPLITUDE metres, WAVES per turn) gives the epipolar lines a vertical component,
so that horizontal edges get depth too.

(Looking outwards from the camera region instead fails: half of the turn faces the south wall
from 0.5 m, whose weak texture gives COLMAP no features.)

Usage: mapper_circle_trajectory.py [SECONDS] [RADIUS] [AMPLITUDE] [WAVES] > circle.txt
Defaults: 18 s, 1.2 m, 0.1 m, 3 (with --fps 5: 90 frames, 4 degrees of the circle apart).
"""
import math
import sys


def normalize(v):
    n = math.sqrt(sum(x * x for x in v))
    return tuple(x / n for x in v)


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def look_at_rotation(position, target):
    """world_from_cam rotation as evloc-sim's LookAtRotation builds it (image y down, z up)."""
    z = normalize(tuple(target[i] - position[i] for i in range(3)))
    x = normalize(cross((0.0, 0.0, -1.0), z))
    y = cross(z, x)
    return [[x[0], y[0], z[0]], [x[1], y[1], z[1]], [x[2], y[2], z[2]]]


def quaternion(m):
    """(qx, qy, qz, qw) of a rotation matrix."""
    trace = m[0][0] + m[1][1] + m[2][2]
    if trace > 0:
        s = math.sqrt(trace + 1.0) * 2
        return ((m[2][1] - m[1][2]) / s, (m[0][2] - m[2][0]) / s, (m[1][0] - m[0][1]) / s, s / 4)
    i = max(range(3), key=lambda k: m[k][k])
    j, k = (i + 1) % 3, (i + 2) % 3
    s = math.sqrt(1.0 + m[i][i] - m[j][j] - m[k][k]) * 2
    q = [0.0, 0.0, 0.0]
    q[i] = s / 4
    q[j] = (m[j][i] + m[i][j]) / s
    q[k] = (m[k][i] + m[i][k]) / s
    return (q[0], q[1], q[2], (m[k][j] - m[j][k]) / s)


def main():
    duration = float(sys.argv[1]) if len(sys.argv) > 1 else 18.0
    radius = float(sys.argv[2]) if len(sys.argv) > 2 else 1.2
    amplitude = float(sys.argv[3]) if len(sys.argv) > 3 else 0.1
    waves = int(sys.argv[4]) if len(sys.argv) > 4 else 3
    start = (0.2, -0.85, 1.45)  # camera_region centre of the default room (docs/sim-scene.md)
    room_centre = (0.0, 0.0, 1.25)  # centre of the room's bounds: the anchor looks at it
    axis = normalize(tuple(room_centre[i] - start[i] for i in range(3)))
    reach = radius / math.hypot(axis[0], axis[1])
    target = tuple(start[i] + reach * axis[i] for i in range(3))
    print(f"# circle: radius {radius:.3f} m around ({target[0]:.4f}, {target[1]:.4f}), looking at "
          f"({target[0]:.4f}, {target[1]:.4f}, {target[2]:.4f}), one turn in {duration:.1f} s, "
          f"height {start[2]:.2f} +- {amplitude:.2f} m with {waves} waves per turn; "
          "t tx ty tz qx qy qz qw (world_from_cam)")
    offset = (start[0] - target[0], start[1] - target[1])
    for i in range(int(round(duration * 1000)) + 1):
        t = i / 1000.0
        phi = 2 * math.pi * t / duration
        c, s = math.cos(phi), math.sin(phi)
        position = (target[0] + c * offset[0] - s * offset[1],
                    target[1] + s * offset[0] + c * offset[1],
                    start[2] + amplitude * math.sin(waves * phi))
        rotation = look_at_rotation(position, target)
        print("%.3f %.6f %.6f %.6f %.9f %.9f %.9f %.9f" % (t, *position, *quaternion(rotation)))


if __name__ == "__main__":
    main()
