"""The tracking status of a step or pose update (docs/tracking.md, docs/api.md)."""

import enum


class Status(enum.IntEnum):
    """TRACKING: the step met the quality thresholds; LOST: it did not (the pose is a guess);
    INITIALIZING: started without a pose, searching the map; RELOCALIZING: lost for good,
    searching the map again. Values are the C++ tracker's (evloc::tracking::TrackingStatus)."""

    TRACKING = 0
    LOST = 1
    INITIALIZING = 2
    RELOCALIZING = 3

    @property
    def has_pose(self):
        """Whether a step with this status carries a pose (searching steps do not)."""
        return self in (Status.TRACKING, Status.LOST)
