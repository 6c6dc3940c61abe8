"""Rotations in 3-D as unit quaternions ``(w, x, y, z)``, vectorized.

Quaternions are ``(..., 4)`` arrays, scalar first (the ``attitude`` port
convention); vectors are ``(..., 3)``. Every function takes the array
namespace ``xp`` and never writes into its arguments.

>>> import numpy as np
>>> q = quat_from_axis_angle(np.array([0.0, 0.0, 1.0]), np.pi / 2)
>>> np.round(quat_rotate(q, np.array([1.0, 0.0, 0.0])), 12)
array([0., 1., 0.])
"""

from __future__ import annotations

import numpy as np


def quat_multiply(a, b, xp=np):
    """Hamilton product ``a * b`` (rotate by ``b`` first, then ``a``)."""
    aw, ax, ay, az = (a[..., i] for i in range(4))
    bw, bx, by, bz = (b[..., i] for i in range(4))
    return xp.stack([aw * bw - ax * bx - ay * by - az * bz,
                     aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw], axis=-1)


def quat_conjugate(q, xp=np):
    """Conjugate (the inverse rotation of a unit quaternion)."""
    return xp.concatenate([q[..., :1], -q[..., 1:]], axis=-1)


def quat_normalize(q, xp=np):
    """Scale quaternions to unit norm."""
    return q / xp.linalg.norm(q, axis=-1, keepdims=True)


def quat_rotate(q, v, xp=np):
    """Rotate vectors ``v`` (..., 3) by unit quaternions ``q`` (..., 4)."""
    w, u = q[..., :1], q[..., 1:]
    t = 2.0 * xp.cross(u, v)
    return v + w * t + xp.cross(u, t)


def quat_to_matrix(q, xp=np):
    """Rotation matrices (..., 3, 3) of unit quaternions (..., 4)."""
    w, x, y, z = (q[..., i] for i in range(4))
    rows = [xp.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            xp.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            xp.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)]
    return xp.stack(rows, axis=-2)


def quat_from_axis_angle(axis, angle, xp=np):
    """Quaternions from unit axes (..., 3) and angles (...) in radians."""
    half = 0.5 * xp.asarray(angle)
    return xp.concatenate([xp.cos(half)[..., None], xp.sin(half)[..., None] * axis],
                          axis=-1)


def quat_from_euler(roll, pitch, yaw, xp=np):
    """Quaternions from Z-Y-X Euler angles (yaw, then pitch, then roll)."""
    cr, sr = xp.cos(0.5 * roll), xp.sin(0.5 * roll)
    cp, sp = xp.cos(0.5 * pitch), xp.sin(0.5 * pitch)
    cy, sy = xp.cos(0.5 * yaw), xp.sin(0.5 * yaw)
    return xp.stack([cr * cp * cy + sr * sp * sy,
                     sr * cp * cy - cr * sp * sy,
                     cr * sp * cy + sr * cp * sy,
                     cr * cp * sy - sr * sp * cy], axis=-1)


def quat_to_euler(q, xp=np):
    """Z-Y-X Euler angles ``(roll, pitch, yaw)`` (..., 3) of unit quaternions."""
    w, x, y, z = (q[..., i] for i in range(4))
    roll = xp.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = xp.arcsin(xp.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = xp.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return xp.stack([roll, pitch, yaw], axis=-1)


__all__ = ["quat_multiply", "quat_conjugate", "quat_normalize", "quat_rotate",
           "quat_to_matrix", "quat_from_axis_angle", "quat_from_euler", "quat_to_euler"]
