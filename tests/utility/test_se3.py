import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.spatial.transform import Rotation

from avblocks.utility import (
    quat_conjugate,
    quat_from_axis_angle,
    quat_from_euler,
    quat_multiply,
    quat_normalize,
    quat_rotate,
    quat_to_euler,
    quat_to_matrix,
)

N = 5
quats = arrays(float, (N, 4), elements=st.floats(-1, 1, allow_nan=False)).filter(
    lambda q: np.all(np.linalg.norm(q, axis=1) > 0.1)).map(quat_normalize)
vecs = arrays(float, (N, 3), elements=st.floats(-10, 10, allow_nan=False))


def scipy_rot(q):
    return Rotation.from_quat(q[:, [1, 2, 3, 0]])   # scipy is scalar-last


@given(quats, vecs)
def test_rotation_matches_scipy(q, v):
    np.testing.assert_allclose(quat_to_matrix(q), scipy_rot(q).as_matrix(), atol=1e-12)
    np.testing.assert_allclose(quat_rotate(q, v), scipy_rot(q).apply(v), atol=1e-9)


@given(quats, quats, vecs)
def test_product_composes_and_conjugate_inverts(a, b, v):
    np.testing.assert_allclose(quat_rotate(quat_multiply(a, b), v),
                               quat_rotate(a, quat_rotate(b, v)), atol=1e-9)
    np.testing.assert_allclose(quat_rotate(quat_conjugate(a), quat_rotate(a, v)), v,
                               atol=1e-9)


@given(arrays(float, (N, 3), elements=st.floats(-1.5, 1.5, allow_nan=False)))
def test_euler_round_trip_and_scipy(e):
    q = quat_from_euler(e[:, 0], e[:, 1], e[:, 2])
    np.testing.assert_allclose(quat_to_matrix(q),
                               Rotation.from_euler("ZYX", e[:, ::-1]).as_matrix(),
                               atol=1e-12)
    np.testing.assert_allclose(quat_to_euler(q), e, atol=1e-7)


def test_axis_angle_exact():
    q = quat_from_axis_angle(np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]),
                             np.array([np.pi / 2, np.pi]))
    np.testing.assert_allclose(quat_rotate(q, np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])),
                               [[0.0, 1.0, 0.0], [0.0, -1.0, 0.0]], atol=1e-15)
