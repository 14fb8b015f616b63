"""What the LiDAR sees: wall segments detected in a merged point cloud (paper §III-A)."""

from .detection import DetectionConfig, detect_segments

__all__ = ["DetectionConfig", "detect_segments"]
