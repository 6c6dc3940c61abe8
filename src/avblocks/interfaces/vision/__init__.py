"""Vision blocks on OpenCV (extra ``[vision]``) and pinhole geometry.

- :class:`ColorBlobTracker`: largest blob of an HSV range per image;
- :class:`PinholeCamera` and functions: pixel -> bearing -> world ray ->
  ground point, and the projection back (NumPy only);
- :class:`GroundPointEstimator`: a block turning a tracked pixel and the
  camera's carrier pose into the ground point it sees.
"""

from .estimator import GroundPointEstimator
from .pinhole import (
    PinholeCamera,
    bearing_to_pixel,
    camera_pose,
    pixel_to_bearing,
    pixel_to_ground,
    pixel_to_ray,
    project,
    ray_ground,
)
from .tracker import ColorBlobTracker, VisionUnavailable, blob_masks, largest_blobs

__all__ = ["ColorBlobTracker", "PinholeCamera", "GroundPointEstimator",
           "VisionUnavailable", "blob_masks", "largest_blobs", "pixel_to_bearing",
           "bearing_to_pixel", "pixel_to_ray", "pixel_to_ground", "ray_ground",
           "project", "camera_pose"]
