"""evloc for Python: maps, events, datasets and the tracker (bindings of evloc's offline library),
a typed client of the evloc-localizer service, and trajectories evo reads. See docs/python.md.

    import evloc
    m = evloc.load_map("maps/room")
    result = evloc.track_dataset(m, "dataset")          # what evloc-track does, in-process
    result.trajectory.save_tum("estimate.txt")          # evo_ape tum groundtruth.txt estimate.txt
"""

from evloc._native import (Error, InvalidArgumentError, IoError, ParseError, event_dtype)
from evloc.status import Status
from evloc.trajectory import Trajectory
from evloc.data import (Map, load_map, read_camera, check_camera, EventReader, open_events,
                        detect_event_format, Dataset, read_dataset, read_events)
from evloc.tracking import Steps, TrackResult, Tracker, track_events, track_dataset
from evloc.client import (Client, Session, Pose, MapDescription, SessionEnd, LocateResult,
                          ServiceError, encode_packed)

__all__ = [
    "Error", "InvalidArgumentError", "IoError", "ParseError", "event_dtype", "Status",
    "Trajectory", "Map", "load_map", "read_camera", "check_camera", "EventReader", "open_events",
    "detect_event_format", "Dataset", "read_dataset", "read_events", "Steps", "TrackResult",
    "Tracker", "track_events", "track_dataset", "Client", "Session", "Pose", "MapDescription",
    "SessionEnd", "LocateResult", "ServiceError", "encode_packed",
]
__version__ = "0.1.0"
