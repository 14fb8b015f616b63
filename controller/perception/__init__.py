"""What the LiDAR sees: wall segments detected in a merged point cloud (paper §III-A),
cleaned of what no wall could give, and handed to the controller each period.

`detection` turns a cloud into segments; `cleaning` drops degenerate, non-finite, duplicate,
absurdly long and out-of-range rows and counts them; `feed` bridges missing scans for a
short while and then says the boat is blind; `tracking` follows other vessels in the points
no wall explains (`clusters`), with a constant-velocity Kalman filter per vessel.
"""

from .cleaning import CleaningConfig, clean_segments
from .detection import DetectionConfig, detect_segments
from .feed import FeedConfig, Percept, PerceptionView, SegmentFeed
from .tracking import Track, TrackerConfig, TrackerOutput, VesselTracker

__all__ = ["CleaningConfig", "DetectionConfig", "FeedConfig", "Percept", "PerceptionView",
           "SegmentFeed", "Track", "TrackerConfig", "TrackerOutput", "VesselTracker",
           "clean_segments", "detect_segments"]
