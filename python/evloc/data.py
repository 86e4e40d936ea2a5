"""Maps, cameras, event files and datasets through evloc's own readers (docs/map-format.md,
docs/event-formats.md, docs/dataset-format.md, docs/camera.md)."""

import os

import numpy as np

from evloc._native import _evloc
from evloc.trajectory import Trajectory

Map = _evloc.Map


def load_map(path):
    """Loads a .evmap file, or a map directory holding map.evmap, with every check of evloc
    (checksums, version, content). Returns an evloc.Map: positions, gradients (N, 3) float32,
    inverse_depth_sigma, gradient_magnitude, source_keyframe (N,), keyframe_cam_from_world
    (K, 4, 4), keyframe_t_ns, keyframe_camera_index, keyframe_image_names, cameras (dicts) and
    summary()."""
    return _evloc.load_map(os.fspath(path))


def read_camera(path, width=0, height=0):
    """Reads a calibration file: an evloc camera YAML, or an ECD calib.txt with width and height.
    Returns the camera as a dict (model, width, height, fx, fy, cx, cy, distortion)."""
    return _evloc.read_camera(os.fspath(path), width, height)


def check_camera(camera):
    """Checks a camera dict as evloc does (raises evloc.InvalidArgumentError) and returns it."""
    return _evloc.check_camera(dict(camera))


class EventReader:
    """The events of a file, in chunks of structured arrays with fields t (int64 ns), x, y
    (uint16) and p (int8: +1 ON, -1 OFF). Iterate over it, or call read()."""

    def __init__(self, native):
        self._native = native

    @property
    def format(self):
        """The detected format ("ECD text", "Prophesee .raw", ...)."""
        return self._native.format

    @property
    def sensor_size(self):
        """(width, height) when the format records it, else None."""
        return self._native.sensor_size

    @property
    def dropped_events(self):
        """Events in the file but not returned (outside the sensor, before a time base)."""
        return self._native.dropped_events

    def read(self, max_events=None):
        """The next chunk (at most max_events, default the reader's chunk size); empty at the
        end. Raises evloc.ParseError / evloc.IoError with the reader's message."""
        return self._native.read(max_events)

    def __iter__(self):
        while True:
            chunk = self._native.read(None)
            if len(chunk) == 0:
                return
            yield chunk

    def read_all(self):
        """Every remaining event in one structured array."""
        chunks = list(self)
        return np.concatenate(chunks) if chunks else np.empty(0, dtype=_evloc.event_dtype)


def open_events(path, chunk_events=1 << 16):
    """Opens an event file of any format evloc reads: ECD text, Prophesee EVT 2.0/3.0 .raw, DSEC
    HDF5, evloc .evb, ROS1 bag (/dvs/events), AEDAT4."""
    return EventReader(_evloc.open_events(os.fspath(path), int(chunk_events)))


def read_events(path):
    """Every event of a file as one structured array (t, x, y, p)."""
    return open_events(path).read_all()


def detect_event_format(path):
    """The format of an event file, as evloc detects it."""
    return _evloc.detect_event_format(os.fspath(path))


class Dataset:
    """A dataset folder, ROS1 bag or AEDAT4 file read by evloc (docs/dataset-format.md)."""

    def __init__(self, path, ecd_size=(240, 180)):
        self.path = os.fspath(path)
        self._ecd_size = tuple(int(v) for v in ecd_size)
        info = _evloc.read_dataset(self.path, *self._ecd_size)
        self.root = info["root"]
        self.camera = info["camera"]
        self.image_t_ns = info["image_t_ns"]
        self.image_paths = info["image_paths"]
        self.events_path = info["events_path"]
        self.ground_truth_map_path = info["ground_truth_map_path"]
        self.ground_truth = Trajectory(*info["ground_truth"]) if info["ground_truth"] else None

    def __repr__(self):
        return (f"Dataset({self.root!r}, camera {self.camera['model']} "
                f"{self.camera['width']}x{self.camera['height']}, "
                f"{len(self.image_paths)} images, events {self.events_path!r}, "
                f"ground truth {len(self.ground_truth) if self.ground_truth else 0} poses)")

    def events(self, chunk_events=1 << 16):
        """A reader of the dataset's events (its event file, the bag's topic, the AEDAT4
        stream)."""
        return EventReader(_evloc.open_dataset_events(self.path, *self._ecd_size,
                                                      int(chunk_events)))

    def initial_pose(self):
        """(t_ns, pose) where evloc-track starts: the first ground-truth pose and its time."""
        return _evloc.dataset_initial_pose(self.path, *self._ecd_size)


def read_dataset(path, ecd_size=(240, 180)):
    """Reads a dataset (see Dataset)."""
    return Dataset(path, ecd_size)
