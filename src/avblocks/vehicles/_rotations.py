"""Rotation helpers for vehicle models, vectorized over agents.

Quaternions are ``(..., 4)`` arrays ``(w, x, y, z)`` (Hamilton convention,
scalar first). ``q`` rotates body-frame vectors into the world frame:
``v_world = R(q) v_body``. Yaw is the ZYX (yaw-pitch-roll) Euler angle.

Every function takes the array namespace ``xp`` and never writes in place.

Reference: J. Sola, "Quaternion kinematics for the error-state Kalman
filter", arXiv:1711.02508 (2017), Sections 2-4.
"""

from __future__ import annotations

import numpy as np


def dot(a, b):
    """Row-wise dot product over the short last axis, ``(..., k) -> (...)``.

    Written out over the k <= 4 components: NumPy's reductions over a short
    trailing axis are ~10x slower than this for large N.
    """
    acc = a[..., 0] * b[..., 0]
    for i in range(1, a.shape[-1]):
        acc = acc + a[..., i] * b[..., i]
    return acc


def cross(a, b, xp=np):
    """Cross product of ``(..., 3)`` arrays (written out: faster than np.cross)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return xp.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def quat_mul(p, q, xp=np):
    """Hamilton product ``p * q`` of ``(..., 4)`` quaternions."""
    pw, px, py, pz = p[..., 0], p[..., 1], p[..., 2], p[..., 3]
    qw, qx, qy, qz = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return xp.stack([
        pw * qw - px * qx - py * qy - pz * qz,
        pw * qx + px * qw + py * qz - pz * qy,
        pw * qy - px * qz + py * qw + pz * qx,
        pw * qz + px * qy - py * qx + pz * qw,
    ], axis=-1)


def quat_conj(q, xp=np):
    """Conjugate (the inverse of a unit quaternion)."""
    return xp.concatenate([q[..., :1], -q[..., 1:]], axis=-1)


def quat_normalize(q, xp=np):
    """Unit quaternion with the same direction (w >= 0 is not enforced)."""
    return q / xp.sqrt(dot(q, q))[..., None]


def quat_rotate(q, v, xp=np):
    """Rotate ``(..., 3)`` vectors ``v`` by unit quaternions ``q``: ``R(q) v``.

    Uses ``v + 2 w (u x v) + 2 u x (u x v)`` with ``u = (x, y, z)``.
    """
    w = q[..., :1]
    u = q[..., 1:]
    t = 2.0 * cross(u, v, xp)
    return v + w * t + cross(u, t, xp)


def quat_to_rotmat(q, xp=np):
    """Rotation matrices ``(..., 3, 3)`` of unit quaternions (body -> world)."""
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    r = xp.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ], axis=-1)
    return xp.reshape(r, (*r.shape[:-1], 3, 3))


def quat_from_euler(roll, pitch, yaw, xp=np):
    """Quaternion of ZYX Euler angles: ``R = Rz(yaw) Ry(pitch) Rx(roll)``."""
    cr, sr = xp.cos(roll / 2), xp.sin(roll / 2)
    cp, sp = xp.cos(pitch / 2), xp.sin(pitch / 2)
    cy, sy = xp.cos(yaw / 2), xp.sin(yaw / 2)
    return xp.stack([
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    ], axis=-1)


def quat_yaw(q, xp=np):
    """ZYX yaw angle of quaternions, in (-pi, pi]."""
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return xp.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def quat_derivative(q, omega, gain=1.0, xp=np):
    """Time derivative of attitude ``q`` under body rates ``omega`` (rad/s).

    ``dq/dt = 1/2 q * (0, omega) + gain (1 - |q|^2) q``.

    The first term is the exact kinematics (Sola 2017, eq. 97). The second is
    zero on the unit sphere and pulls ``|q|`` back to 1 when integration
    error drifts it: with ``s = |q|^2``, ``ds/dt = 2 gain (1 - s) s``, a
    stable equilibrium at ``s = 1`` (time constant ``1 / (2 gain)``). It is
    the Baumgarte-style stabilization of e.g. Markley & Crassidis,
    *Fundamentals of Spacecraft Attitude Determination and Control* (2014),
    Section 3.3.
    """
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    p, r_, s = omega[..., 0], omega[..., 1], omega[..., 2]
    dq = 0.5 * xp.stack([
        -x * p - y * r_ - z * s,
        w * p + y * s - z * r_,
        w * r_ - x * s + z * p,
        w * s + x * r_ - y * p,
    ], axis=-1)
    n2 = dot(q, q)[..., None]
    return dq + gain * (1.0 - n2) * q


def vee(m, xp=np):
    """The vector ``(..., 3)`` of a skew-symmetric matrix ``(..., 3, 3)``."""
    return xp.stack([m[..., 2, 1], m[..., 0, 2], m[..., 1, 0]], axis=-1)
