"""Timed camera poses (world_from_cam) and their TUM files, the format evo reads
(`evo_ape tum groundtruth.txt estimate.txt`): one line `t tx ty tz qx qy qz qw` per pose, t in
seconds. Written and read by evloc's own C++ code, so a file is byte for byte what evloc-track and
evloc-replay write (times as exact decimals of nanoseconds), and written atomically."""

import os

import numpy as np

from evloc._native import _evloc


def _rotation_matrices(quaternions_xyzw):
    x, y, z, w = (quaternions_xyzw[:, i] for i in range(4))
    matrices = np.empty((len(quaternions_xyzw), 3, 3))
    matrices[:, 0, 0] = 1 - 2 * (y * y + z * z)
    matrices[:, 0, 1] = 2 * (x * y - z * w)
    matrices[:, 0, 2] = 2 * (x * z + y * w)
    matrices[:, 1, 0] = 2 * (x * y + z * w)
    matrices[:, 1, 1] = 1 - 2 * (x * x + z * z)
    matrices[:, 1, 2] = 2 * (y * z - x * w)
    matrices[:, 2, 0] = 2 * (x * z - y * w)
    matrices[:, 2, 1] = 2 * (y * z + x * w)
    matrices[:, 2, 2] = 1 - 2 * (x * x + y * y)
    return matrices


def poses_to_matrices(poses):
    """(N, 7) poses `tx ty tz qx qy qz qw` to (N, 4, 4) homogeneous matrices."""
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 7)
    matrices = np.zeros((len(poses), 4, 4))
    matrices[:, :3, :3] = _rotation_matrices(poses[:, 3:7])
    matrices[:, :3, 3] = poses[:, :3]
    matrices[:, 3, 3] = 1.0
    return matrices


class Trajectory:
    """Poses world_from_cam at times t_ns: `t_ns` (N,) int64 nanoseconds, `poses` (N, 7) float64
    `tx ty tz qx qy qz qw` (the TUM order)."""

    def __init__(self, t_ns=(), poses=()):
        self.t_ns = np.asarray(t_ns, dtype=np.int64).reshape(-1)
        self.poses = np.asarray(poses, dtype=np.float64).reshape(-1, 7)
        if len(self.t_ns) != len(self.poses):
            raise ValueError(f"Trajectory: {len(self.t_ns)} times but {len(self.poses)} poses")

    def __len__(self):
        return len(self.t_ns)

    def __repr__(self):
        if not len(self):
            return "Trajectory(0 poses)"
        return (f"Trajectory({len(self)} poses, {self.t_ns[0] * 1e-9:.6f} s to "
                f"{self.t_ns[-1] * 1e-9:.6f} s)")

    @property
    def timestamps(self):
        """Times in seconds (float64), as evo's PoseTrajectory3D holds them."""
        return self.t_ns * 1e-9

    @property
    def positions(self):
        """(N, 3) camera centres in the world frame, metres."""
        return self.poses[:, :3]

    @property
    def quaternions_xyzw(self):
        """(N, 4) orientations, x y z w (TUM order)."""
        return self.poses[:, 3:7]

    @property
    def quaternions_wxyz(self):
        """(N, 4) orientations, w x y z (evo's order)."""
        return self.poses[:, [6, 3, 4, 5]]

    def matrices(self):
        """(N, 4, 4) homogeneous world_from_cam matrices."""
        return poses_to_matrices(self.poses)

    def to_tum_text(self):
        """The TUM file's text, as save_tum writes it."""
        return _evloc.format_tum(self.t_ns, self.poses)

    def save_tum(self, path):
        """Writes a TUM file (atomically: a temporary name, then renamed)."""
        _evloc.write_tum(os.fspath(path), self.t_ns, self.poses)

    @classmethod
    def load_tum(cls, path):
        """Reads a TUM file (`#` comments allowed); raises evloc.ParseError naming the line."""
        t_ns, poses = _evloc.read_tum(os.fspath(path))
        return cls(t_ns, poses)

    def to_evo(self):
        """An evo.core.trajectory.PoseTrajectory3D (needs the evo package)."""
        from evo.core.trajectory import PoseTrajectory3D  # pylint: disable=import-outside-toplevel
        return PoseTrajectory3D(positions_xyz=self.positions.copy(),
                                orientations_quat_wxyz=self.quaternions_wxyz.copy(),
                                timestamps=self.timestamps.copy())
