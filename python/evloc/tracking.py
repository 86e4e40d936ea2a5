"""The tracker of evloc-track and the service, in-process (docs/tracking.md).

Options are evloc-track's flags by name, dashes as underscores: `rate=300` is `--rate 300`,
`variant="EVT-PR"`, `polarity=False` is `--polarity off`, `max_points=2500`. They go through
evloc-track's own parser, so they mean the same and a bad value raises evloc-track's message.
Tracking runs with the GIL released."""

import os
import tempfile

import numpy as np

from evloc._native import _evloc
from evloc.data import Dataset, Map
from evloc.status import Status
from evloc.trajectory import Trajectory, poses_to_matrices


def flags_from_options(options):
    """evloc-track flags from keyword options (see the module's docstring)."""
    flags = []
    for name, value in options.items():
        if value is None:
            continue
        flag = "--" + name.replace("_", "-")
        if isinstance(value, bool):
            flags += [flag, "on" if value else "off"]
        elif isinstance(value, (list, tuple, np.ndarray)):
            flags += [flag, " ".join(repr(float(v)) for v in value)]
        else:
            flags += [flag, str(value)]
    return flags


class Steps:
    """Per-step results (the columns of evloc-track --stats), one element per step: t_ns,
    status (Status codes), pose (N, 7) `tx ty tz qx qy qz qw`, covariance (N, 6, 6) of
    xi = (v, omega) in world_from_cam * Exp(xi), points_selected, points_used, iterations,
    recovery_attempts, on_edge_fraction, chance_on_edge_fraction, alignment, mean_residual,
    decay_time_ms, surface_age_ms, surface_ms, selection_ms, solve_ms, total_ms."""

    def __init__(self, columns):
        self._columns = dict(columns)

    def __getattr__(self, name):
        try:
            return self.__dict__["_columns"][name]
        except KeyError:
            raise AttributeError(name) from None

    def __len__(self):
        return len(self._columns["t_ns"])

    def __repr__(self):
        counts = {s.name: int(np.sum(self.status == s)) for s in Status}
        return f"Steps({len(self)}: " + ", ".join(f"{k} {v}" for k, v in counts.items() if v) + ")"

    @property
    def columns(self):
        """The column names."""
        return list(self._columns)

    @property
    def statuses(self):
        """The statuses as a list of Status."""
        return [Status(int(code)) for code in self.status]

    def matrices(self):
        """(N, 4, 4) world_from_cam of every step (meaningless where the status has no pose)."""
        return poses_to_matrices(self.pose)

    def as_dict(self):
        """The columns as a dict of arrays."""
        return dict(self._columns)


class TrackResult:
    """What a run produced: `trajectory` (a Trajectory of the steps with a pose, what evloc-track
    writes), `steps` (Steps), `measurements` (events read), `lost_steps`, `wall_s`,
    `relocalizations` (search episodes), `log` (evloc-track's progress text, track_dataset)."""

    def __init__(self, native):
        self.trajectory = Trajectory(*native["trajectory"])
        self.steps = Steps(native["steps"])
        self.measurements = native["measurements"]
        self.lost_steps = native["lost_steps"]
        self.wall_s = native["wall_s"]
        self.relocalizations = native["relocalizations"]
        self.log = native.get("log", "")

    def __repr__(self):
        return (f"TrackResult({len(self.steps)} steps, {self.lost_steps} LOST, "
                f"{self.measurements} events, {self.wall_s:.3f} s)")

    @property
    def median_step_ms(self):
        """Median wall time of a step, ms (evloc-track's "median step")."""
        return float(np.median(self.steps.total_ms)) if len(self.steps) else 0.0


def _event_arrays(events):
    """(t, x, y, p) arrays from a structured array (fields t, x, y, p), a dict or a 4-tuple."""
    if isinstance(events, np.ndarray) and events.dtype.names:
        missing = {"t", "x", "y", "p"} - set(events.dtype.names)
        if missing:
            raise ValueError(f"events: the structured array lacks the fields {sorted(missing)} "
                             "(expected t, x, y, p)")
        return events["t"], events["x"], events["y"], events["p"]
    if isinstance(events, dict):
        return events["t"], events["x"], events["y"], events["p"]
    if isinstance(events, (tuple, list)) and len(events) == 4:
        return tuple(events)
    raise TypeError("events: expected a structured array with fields t, x, y, p (evloc."
                    "event_dtype), a dict of those arrays or a tuple (t, x, y, p)")


def _checked_int8(values):
    values = np.asarray(values)
    if values.dtype != np.int8 and len(values) and (values.min() < -1 or values.max() > 1):
        raise ValueError("events: polarity must be 1 (ON), 0 or -1 (OFF)")
    return values.astype(np.int8, copy=False)


def _checked_uint16(values, name):
    values = np.asarray(values)
    if values.dtype != np.uint16 and len(values) and (values.min() < 0 or values.max() > 65535):
        raise ValueError(f"events: {name} must lie in 0..65535")
    return values.astype(np.uint16, copy=False)


def _native_events(events):
    t, x, y, p = _event_arrays(events)
    return (np.asarray(t, dtype=np.int64), _checked_uint16(x, "x"), _checked_uint16(y, "y"),
            _checked_int8(p))


def _map(map_or_path):
    return map_or_path if isinstance(map_or_path, Map) else _evloc.load_map(os.fspath(map_or_path))


def _pose(pose):
    return None if pose is None else np.asarray(pose, dtype=np.float64)


class Tracker:
    """A live tracker: reset(pose, t_ns) (or start_without_pose(t_ns)), then add_events(events)
    chunk by chunk; each call returns the Steps that became due."""

    def __init__(self, map, camera, **options):  # pylint: disable=redefined-builtin
        self._native = _evloc.Tracker(_map(map), dict(camera), flags_from_options(options))

    def reset(self, pose, t_ns):
        """Sets the pose (7 values tx ty tz qx qy qz qw, or a 4x4 world_from_cam) at t_ns."""
        self._native.reset(_pose(pose), int(t_ns))

    def start_without_pose(self, t_ns):
        """Starts INITIALIZING at t_ns: the steps search the map until a pose is verified."""
        self._native.start_without_pose(int(t_ns))

    def add_events(self, events):
        """Ingests time-ordered events and runs the steps that became due."""
        return Steps(self._native.add_events(*_native_events(events)))

    def advance_to(self, t_ns):
        """Declares every event up to t_ns given: runs the steps due by then."""
        return Steps(self._native.advance_to(int(t_ns)))

    @property
    def status(self):
        """The status after the last step."""
        return Status[self._native.status]


def track_events(map, camera, events, initial_pose, initial_t_ns,  # pylint: disable=redefined-builtin
                 **options):
    """Tracks events (structured array, dict or (t, x, y, p) tuple, time-ordered) against `map`
    (an evloc.Map or a path) with `camera` (a dict, e.g. Dataset.camera) from `initial_pose`
    at `initial_t_ns` (None: start without a pose and search the map), as evloc-track does with
    a file of these events. Returns a TrackResult."""
    native = _evloc.track_events(_map(map), dict(camera), *_native_events(events),
                                 _pose(initial_pose), int(initial_t_ns),
                                 flags_from_options(options))
    return TrackResult(native)


def track_dataset(map, dataset, out=None, *, init_pose=None,  # pylint: disable=redefined-builtin
                  stats=None, **options):
    """Runs evloc-track on a dataset in-process: the same parser, run and files (`out`: the TUM
    trajectory, `stats`: the JSON statistics; without `out` the trajectory is only returned).
    `init_pose`: 7 values, a 4x4 matrix or "none"; default the first ground-truth pose. Further
    options are evloc-track's flags (start=0.5, blackout=(0.2, 0.4), ecd_size="240x180", ...).
    Returns a TrackResult."""
    map_path = map.source if isinstance(map, Map) else os.fspath(map)
    dataset_path = dataset.path if isinstance(dataset, Dataset) else os.fspath(dataset)
    if "blackout" in options and isinstance(options["blackout"], (tuple, list)):
        begin, end = options["blackout"]
        options["blackout"] = f"{float(begin)!r}:{float(end)!r}"
    arguments = ["--map", map_path, "--dataset", dataset_path, "--quiet"]
    if init_pose is not None:
        if isinstance(init_pose, str):
            arguments += ["--init-pose", init_pose]
        else:
            pose = np.asarray(init_pose, dtype=np.float64)
            if pose.shape == (4, 4):
                trajectory = Trajectory([0], [_matrix_to_pose(pose)])
                pose = trajectory.poses[0]
            arguments += ["--init-pose", " ".join(repr(float(v)) for v in pose.reshape(-1))]
    if stats is not None:
        arguments += ["--stats", os.fspath(stats)]
    arguments += flags_from_options(options)
    if out is not None:
        return TrackResult(_evloc.track_command(arguments + ["--out", os.fspath(out)]))
    with tempfile.TemporaryDirectory(prefix="evloc-track-") as folder:
        return TrackResult(_evloc.track_command(
            arguments + ["--out", os.path.join(folder, "trajectory.txt")]))


def _matrix_to_pose(matrix):
    """7 values tx ty tz qx qy qz qw of a 4x4 rigid matrix."""
    rotation = matrix[:3, :3]
    trace = np.trace(rotation)
    if trace > 0:
        s = 2.0 * np.sqrt(trace + 1.0)
        w = 0.25 * s
        x = (rotation[2, 1] - rotation[1, 2]) / s
        y = (rotation[0, 2] - rotation[2, 0]) / s
        z = (rotation[1, 0] - rotation[0, 1]) / s
    else:
        i = int(np.argmax(np.diag(rotation)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + rotation[i, i] - rotation[j, j] - rotation[k, k])
        q = np.zeros(3)
        q[i] = 0.25 * s
        q[j] = (rotation[j, i] + rotation[i, j]) / s
        q[k] = (rotation[k, i] + rotation[i, k]) / s
        w = (rotation[k, j] - rotation[j, k]) / s
        x, y, z = q
    return [matrix[0, 3], matrix[1, 3], matrix[2, 3], x, y, z, w]
