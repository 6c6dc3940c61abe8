"""The one place where MAVLink's frames meet the library's.

MAVLink local frame: NED (x north, y east, z down), body FRD (x forward,
y right, z down), heading clockwise from north. The library's world frame:
ENU (x east, y north, z up), body FLU (x forward, y left, z up), yaw
counter-clockwise from east. Each vehicle's local NED frame has its origin
at ``origin`` (ENU, world frame); by default the world origin (a lab whose
motion capture feeds every autopilot the same frame).

::

    p_enu = origin + (y_ned, x_ned, -z_ned)        v_enu = (vy_ned, vx_ned, -vz_ned)
    yaw_enu = pi/2 - yaw_ned
    R_enu_flu = A R_ned_frd B,  A = [[0,1,0],[1,0,0],[0,0,-1]],  B = diag(1,-1,-1)

``A`` (swap x, y; negate z) is its own inverse, so the same functions
convert both ways. Quaternions are (w, x, y, z); ``A`` is the rotation by
pi about (1, 1, 0)/sqrt 2, quaternion (0, 1/sqrt 2, 1/sqrt 2, 0), ``B``
the rotation by pi about x, quaternion (0, 1, 0, 0).

References
----------
MAVLink common message set (``MAV_FRAME_LOCAL_NED``, ``LOCAL_POSITION_NED``,
``ATTITUDE_QUATERNION``); REP 103 (ENU/FLU conventions).
"""

from __future__ import annotations

import numpy as np

_S = np.sqrt(0.5)
_QA = np.array([0.0, _S, _S, 0.0])
_QB = np.array([0.0, 1.0, 0.0, 0.0])


def _qmul(a, b):
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack([aw * bw - ax * bx - ay * by - az * bz,
                     aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw], axis=-1)


def ned_to_enu(v):
    """A vector (..., 3) from NED to ENU (and back: the map is an involution)."""
    v = np.asarray(v, float)
    return np.stack([v[..., 1], v[..., 0], -v[..., 2]], axis=-1)


enu_to_ned = ned_to_enu


def position_to_world(p_ned, origin=0.0):
    """Local NED position (..., 3) -> world ENU (..., 3)."""
    return np.asarray(origin, float) + ned_to_enu(p_ned)


def position_to_local(p_enu, origin=0.0):
    """World ENU position (..., 3) -> local NED (..., 3)."""
    return enu_to_ned(np.asarray(p_enu, float) - np.asarray(origin, float))


def yaw_to_enu(yaw_ned):
    """Heading (clockwise from north) -> yaw (counter-clockwise from east),
    wrapped to (-pi, pi]; and back (the same map)."""
    y = np.pi / 2 - np.asarray(yaw_ned, float)
    return np.arctan2(np.sin(y), np.cos(y))


yaw_to_ned = yaw_to_enu


def quat_to_enu(q_ned):
    """Attitude (w, x, y, z) body FRD -> NED  =>  body FLU -> ENU (and back)."""
    q = _qmul(_qmul(_QA, np.asarray(q_ned, float)), _QB)
    return q * np.where(q[..., :1] < 0, -1.0, 1.0)     # w >= 0


quat_to_ned = quat_to_enu
