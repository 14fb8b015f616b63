"""OpenCV as perception uses it: imported on first use, with its thread pool set to one
thread.

A scan's images are small (240 x 240 clustering cells, 600 x 600 Hough cells): handing such
an image to a pool costs more CPU than the work it shares. Measured in the closed loop
(Pohang, LiDAR): `connectedComponents` 0.63 ms of CPU per scan with OpenCV's default pool,
0.08 ms with one thread; the results are the same (the labels do not depend on the threads).
The setting is OpenCV's, process-wide: a program that wants the pool for its own images sets
`cv2.setNumThreads` again after perception's first call.
"""

from __future__ import annotations

_cv2 = None


def cv2():
    """The `cv2` module, set to one thread the first time it is asked for."""
    global _cv2
    if _cv2 is None:
        import cv2 as module

        module.setNumThreads(1)
        _cv2 = module
    return _cv2
