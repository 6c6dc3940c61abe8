"""Rigid motions of the plane, SE(2), vectorized over poses.

A pose is ``(x, y, theta)`` on the last axis: one pose ``(3,)`` or N poses
``(N, 3)`` (any leading axes broadcast). Points are ``(..., 2)``. Every
function takes the array namespace ``xp`` (NumPy by default), never writes
into its arguments, and returns headings wrapped to (-pi, pi].

Conventions: a pose ``p`` is the transform from its body frame to the world
frame, ``w = R(theta) b + (x, y)``. ``se2_compose(a, b)`` is ``a * b``: the
pose ``b`` expressed in frame ``a``, taken to the world frame.

>>> import numpy as np
>>> a = np.array([1.0, 0.0, np.pi / 2])
>>> np.round(body_to_world(a, np.array([1.0, 0.0])), 12)
array([1., 1.])
>>> np.round(se2_compose(a, se2_inverse(a)), 12)
array([0., 0., 0.])
"""

from __future__ import annotations

import numpy as np

from .angles import wrap_angle


def rotate(theta, v, xp=np):
    """Rotate 2-D vectors ``v`` (..., 2) by angles ``theta`` (...)."""
    c, s = xp.cos(theta), xp.sin(theta)
    vx, vy = v[..., 0], v[..., 1]
    return xp.stack([c * vx - s * vy, s * vx + c * vy], axis=-1)


def se2_compose(a, b, xp=np):
    """Composition ``a * b`` of poses (..., 3)."""
    xy = a[..., :2] + rotate(a[..., 2], b[..., :2], xp)
    th = wrap_angle(a[..., 2] + b[..., 2], xp)
    return xp.concatenate([xy, th[..., None]], axis=-1)


def se2_inverse(p, xp=np):
    """Inverse pose: ``se2_compose(p, se2_inverse(p))`` is the identity."""
    th = p[..., 2]
    xy = -rotate(-th, p[..., :2], xp)
    return xp.concatenate([xy, wrap_angle(-th, xp)[..., None]], axis=-1)


def se2_relative(a, b, xp=np):
    """Pose of ``b`` in the body frame of ``a``: ``inverse(a) * b``.

    E.g. where a follower's leader sits as seen from the follower.
    """
    return se2_compose(se2_inverse(a, xp), b, xp)


def body_to_world(pose, points, xp=np):
    """Points (..., 2) given in the body frame of ``pose`` -> world frame."""
    return pose[..., :2] + rotate(pose[..., 2], points, xp)


def world_to_body(pose, points, xp=np):
    """World points (..., 2) -> the body frame of ``pose``.

    For many points per agent, add an axis: ``world_to_body(pose[:, None], pts)``
    with ``pts`` of shape (N, M, 2).
    """
    return rotate(-pose[..., 2], points - pose[..., :2], xp)


def _velocity(theta, v, xp):
    lin = rotate(theta, v[..., :2], xp)
    if v.shape[-1] == 2:
        return lin
    if v.shape[-1] != 3:
        raise ValueError(f"velocity must have 2 (vx, vy) or 3 (vx, vy, omega) "
                         f"components, found shape {v.shape}")
    return xp.concatenate([lin, v[..., 2:3]], axis=-1)


def velocity_body_to_world(pose, v, xp=np):
    """Body-frame velocity (vx, vy) or twist (vx, vy, omega) -> world frame.

    The linear part is rotated by the heading; the turn rate is the same in
    both frames.
    """
    return _velocity(pose[..., 2], v, xp)


def velocity_world_to_body(pose, v, xp=np):
    """World-frame velocity (vx, vy) or (vx, vy, omega) -> body frame."""
    return _velocity(-pose[..., 2], v, xp)


def se2_to_matrix(pose, xp=np):
    """Homogeneous 3x3 matrices (..., 3, 3) of poses (..., 3)."""
    c, s = xp.cos(pose[..., 2]), xp.sin(pose[..., 2])
    z, o = 0.0 * c, 0.0 * c + 1.0
    rows = [xp.stack([c, -s, pose[..., 0]], axis=-1),
            xp.stack([s, c, pose[..., 1]], axis=-1),
            xp.stack([z, z, o], axis=-1)]
    return xp.stack(rows, axis=-2)


def se2_from_matrix(m, xp=np):
    """Poses (..., 3) from homogeneous matrices (..., 3, 3)."""
    th = xp.arctan2(m[..., 1, 0], m[..., 0, 0])
    return xp.stack([m[..., 0, 2], m[..., 1, 2], wrap_angle(th, xp)], axis=-1)


__all__ = ["rotate", "se2_compose", "se2_inverse", "se2_relative", "body_to_world",
           "world_to_body", "velocity_body_to_world", "velocity_world_to_body",
           "se2_to_matrix", "se2_from_matrix"]
