"""Pinhole camera geometry: pixels <-> bearings <-> world rays <-> ground points.

Conventions (OpenCV's): camera frame x right, y down, z forward (along the
optical axis); pixel ``(u, v)`` = (column, row), pixel centres at integers,
row 0 at the top; intrinsics ``K = [[fx, s, cx], [0, fy, cy], [0, 0, 1]]``.
A camera pose is its world position ``c`` (3,) and the rotation ``R``
(3, 3) whose columns are the camera axes in the world (camera -> world).

Equations
---------
::

    bearing      b = K^-1 (u, v, 1)^T            (camera frame, z = 1)
    world ray    d = R b / |R b|,  from c
    ground hit   p = c + s d,  s = (z0 - c_z) / d_z   (s > 0 required)
    projection   (u, v, 1)^T ~ K R^T (p - c)       (in front: z_cam > 0)

Vectorized: ``K`` (3, 3) or (N, 3, 3), ``c`` (N, 3), ``R`` (N, 3, 3),
pixels (N, 2). Reference: Hartley & Zisserman, *Multiple View Geometry*,
2nd ed. (2004), Section 6.1; OpenCV's camera model (``cv2.projectPoints``).
"""

from __future__ import annotations

import numpy as np

from ...core.errors import ParameterError


def _K(K):
    K = np.asarray(K, float)
    if K.shape[-2:] != (3, 3):
        raise ParameterError("intrinsic matrix must be (3, 3) or (N, 3, 3)",
                             param="K", found=K.shape)
    return K


def pixel_to_bearing(pixels, K):
    """Pixels (N, 2) -> bearings (N, 3) in the camera frame (z = 1)."""
    K = _K(K)
    px = np.asarray(pixels, float)
    h = np.concatenate([px, np.ones(px.shape[:-1] + (1,))], axis=-1)
    Kinv = np.linalg.inv(K)
    return np.einsum("...ij,...j->...i", Kinv, h)


def bearing_to_pixel(bearings, K):
    """Camera-frame points or bearings (N, 3) with z > 0 -> pixels (N, 2)."""
    K = _K(K)
    b = np.asarray(bearings, float)
    h = np.einsum("...ij,...j->...i", K, b)
    return h[..., :2] / h[..., 2:3]


def pixel_to_ray(pixels, K, R):
    """Unit world-frame ray directions (N, 3) through pixels (N, 2)."""
    b = pixel_to_bearing(pixels, K)
    d = np.einsum("...ij,...j->...i", np.asarray(R, float), b)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def ray_ground(origin, direction, z0=0.0):
    """Intersections (N, 3) of rays with the plane z = z0 and a flag (N,):
    True where the ray hits it in front of the origin (else the point is NaN)."""
    c = np.asarray(origin, float)
    d = np.asarray(direction, float)
    dz = d[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (z0 - c[..., 2]) / dz
    ok = np.isfinite(s) & (s > 0)
    p = c + np.where(ok, s, np.nan)[..., None] * d
    return p, ok


def pixel_to_ground(pixels, K, position, R, z0=0.0):
    """Ground points (N, 3) seen at pixels (N, 2) by cameras at ``position``
    (N, 3) with rotations ``R`` (N, 3, 3); returns ``(points, ok)``."""
    return ray_ground(position, pixel_to_ray(pixels, K, R), z0)


def project(points, K, position, R):
    """World points (N, 3) -> pixels (N, 2) and an in-front flag (N,)."""
    pc = np.einsum("...ji,...j->...i", np.asarray(R, float),
                   np.asarray(points, float) - np.asarray(position, float))
    front = pc[..., 2] > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        px = bearing_to_pixel(pc, K)
    return px, front


def camera_pose(body_position, body_attitude, mount_pos, mount_rot):
    """Camera poses from body poses: position (N, 3) and OpenCV rotation
    (N, 3, 3), for a camera at ``mount_pos`` (3,) in the body frame with
    axes ``mount_rot`` (3, 3) (MuJoCo convention: columns x right, y up,
    z backwards, as :meth:`~avblocks.interfaces.mujoco.CameraMount.rotation`)."""
    from ...vehicles import quat_normalize, quat_to_rotmat
    q = quat_normalize(np.asarray(body_attitude, float))
    Rb = quat_to_rotmat(q)
    pos = np.asarray(body_position, float) + Rb @ np.asarray(mount_pos, float)
    R = Rb @ np.asarray(mount_rot, float) @ np.diag([1.0, -1.0, -1.0])
    return pos, R


class PinholeCamera:
    """A pinhole camera with intrinsics ``K``: the functions above as methods.

    >>> import numpy as np
    >>> cam = PinholeCamera.from_fov(60.0, 320, 240)
    >>> R = np.diag([1.0, -1.0, -1.0])[None]      # looking straight down
    >>> p, ok = cam.pixel_to_ground([[159.5, 119.5]], [[1.0, 2.0, 3.0]], R)
    >>> p.round(9).tolist(), ok.tolist()
    ([[1.0, 2.0, 0.0]], [True])
    """

    def __init__(self, K, width=None, height=None):
        self.K = _K(K).copy()
        self.width, self.height = width, height

    @classmethod
    def from_fov(cls, fovy_deg, width, height):
        """Square pixels, principal point at the image centre, vertical FOV."""
        f = 0.5 * height / np.tan(np.deg2rad(fovy_deg) / 2)
        K = np.array([[f, 0.0, (width - 1) / 2], [0.0, f, (height - 1) / 2],
                      [0.0, 0.0, 1.0]])
        return cls(K, width, height)

    def pixel_to_bearing(self, pixels):
        return pixel_to_bearing(pixels, self.K)

    def bearing_to_pixel(self, bearings):
        return bearing_to_pixel(bearings, self.K)

    def pixel_to_ray(self, pixels, R):
        return pixel_to_ray(pixels, self.K, R)

    def pixel_to_ground(self, pixels, position, R, z0=0.0):
        return pixel_to_ground(pixels, self.K, position, R, z0)

    def project(self, points, position, R):
        return project(points, self.K, position, R)

    def in_image(self, pixels):
        """(N,) True where pixels lie inside the image (needs width, height)."""
        px = np.asarray(pixels, float)
        return ((px[..., 0] >= -0.5) & (px[..., 0] <= self.width - 0.5)
                & (px[..., 1] >= -0.5) & (px[..., 1] <= self.height - 0.5))
