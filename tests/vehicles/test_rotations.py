"""Quaternion helpers: property tests against independent formulas."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from avblocks.vehicles import _rotations as rot

angle = st.floats(-3.1, 3.1)
comp = st.floats(-1, 1)


def rz(a):
    return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])


def ry(a):
    return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])


def rx(a):
    return np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])


@settings(max_examples=60, deadline=None)
@given(angle, st.floats(-1.5, 1.5), angle, comp, comp, comp)
def test_euler_matrix_rotate_yaw(roll, pitch, yaw, a, b, c):
    q = rot.quat_from_euler(np.array([roll]), np.array([pitch]), np.array([yaw]))
    R = rz(yaw) @ ry(pitch) @ rx(roll)
    np.testing.assert_allclose(rot.quat_to_rotmat(q)[0], R, atol=1e-12)
    v = np.array([[a, b, c]])
    np.testing.assert_allclose(rot.quat_rotate(q, v)[0], R @ v[0], atol=1e-12)
    np.testing.assert_allclose(rot.quat_yaw(q)[0], yaw, atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(angle, angle, angle, angle, angle, angle)
def test_product_composes_rotations(r1, p1, y1, r2, p2, y2):
    q1 = rot.quat_from_euler(np.array([r1]), np.array([p1]), np.array([y1]))
    q2 = rot.quat_from_euler(np.array([r2]), np.array([p2]), np.array([y2]))
    R12 = rot.quat_to_rotmat(q1)[0] @ rot.quat_to_rotmat(q2)[0]
    np.testing.assert_allclose(rot.quat_to_rotmat(rot.quat_mul(q1, q2))[0], R12, atol=1e-12)
    np.testing.assert_allclose(rot.quat_mul(q1, rot.quat_conj(q1))[0], [1, 0, 0, 0],
                               atol=1e-12)


def test_derivative_is_body_rate_kinematics():
    # rotating about body z at rate w from yaw a: q(t) = (cos((a+wt)/2), 0, 0, sin(...))
    a, w = 0.4, 1.3
    q = np.array([[np.cos(a / 2), 0, 0, np.sin(a / 2)]])
    dq = rot.quat_derivative(q, np.array([[0, 0, w]]))
    np.testing.assert_allclose(dq[0], [-w / 2 * np.sin(a / 2), 0, 0, w / 2 * np.cos(a / 2)])
