import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from avblocks.utility import (
    angle_diff,
    body_to_world,
    rotate,
    se2_compose,
    se2_from_matrix,
    se2_inverse,
    se2_relative,
    se2_to_matrix,
    velocity_body_to_world,
    velocity_world_to_body,
    world_to_body,
    wrap_angle,
)

angles = st.floats(-1e4, 1e4, allow_nan=False)
coords = st.floats(-100, 100, allow_nan=False)
N = 6


def poses(n=N):
    return arrays(float, (n, 3), elements=coords).map(
        lambda p: np.concatenate([p[:, :2], wrap_angle(p[:, 2:])], axis=1))


def points(n=N):
    return arrays(float, (n, 2), elements=coords)


def same_pose(a, b, tol=1e-9):
    np.testing.assert_allclose(a[..., :2], b[..., :2], atol=tol)
    np.testing.assert_allclose(wrap_angle(a[..., 2] - b[..., 2]), 0.0, atol=tol)


@given(arrays(float, 20, elements=angles))
def test_wrap_angle_range_and_idempotence(a):
    w = wrap_angle(a)
    assert np.all(w > -np.pi) and np.all(w <= np.pi)
    np.testing.assert_array_equal(wrap_angle(w), w)
    # same direction as the input
    np.testing.assert_allclose(np.cos(w), np.cos(a), atol=1e-9)
    np.testing.assert_allclose(np.sin(w), np.sin(a), atol=1e-9)


def test_wrap_angle_edges():
    assert wrap_angle(np.pi) == np.pi and wrap_angle(-np.pi) == np.pi
    assert wrap_angle(0.0) == 0.0
    assert abs(angle_diff(np.pi - 0.1, -np.pi + 0.1) - (-0.2)) < 1e-12


@given(poses(), poses(), poses())
def test_compose_associative_identity_inverse(a, b, c):
    same_pose(se2_compose(se2_compose(a, b), c), se2_compose(a, se2_compose(b, c)), 1e-7)
    e = np.zeros(3)
    same_pose(se2_compose(a, e), a)
    same_pose(se2_compose(e, a), a)
    same_pose(se2_compose(a, se2_inverse(a)), np.zeros_like(a), 1e-9)
    same_pose(se2_compose(se2_inverse(a), a), np.zeros_like(a), 1e-9)
    same_pose(se2_inverse(se2_inverse(a)), a)
    same_pose(se2_compose(a, se2_relative(a, b)), b, 1e-7)


@given(poses(), poses())
def test_compose_matches_homogeneous_matrices(a, b):
    m = se2_to_matrix(a) @ se2_to_matrix(b)
    same_pose(se2_from_matrix(m), se2_compose(a, b), 1e-7)
    same_pose(se2_from_matrix(np.linalg.inv(se2_to_matrix(a))), se2_inverse(a), 1e-7)


@given(poses(), points())
def test_point_transforms_round_trip_and_match_matrices(p, q):
    w = body_to_world(p, q)
    np.testing.assert_allclose(world_to_body(p, w), q, atol=1e-9)
    h = np.concatenate([q, np.ones((N, 1))], axis=1)
    np.testing.assert_allclose(w, np.einsum("nij,nj->ni", se2_to_matrix(p), h)[:, :2],
                               atol=1e-9)
    # distances are preserved
    np.testing.assert_allclose(np.linalg.norm(w - p[:, :2], axis=1),
                               np.linalg.norm(q, axis=1), atol=1e-9)


@given(poses(), arrays(float, (N, 3), elements=coords))
def test_velocity_transforms_round_trip(p, v):
    vw = velocity_body_to_world(p, v)
    np.testing.assert_allclose(vw[:, 2], v[:, 2])
    np.testing.assert_allclose(velocity_world_to_body(p, vw), v, atol=1e-9)
    np.testing.assert_allclose(velocity_body_to_world(p, v[:, :2]), vw[:, :2])


def test_exact_values_and_broadcasting():
    p = np.array([[1.0, 2.0, np.pi / 2], [0.0, 0.0, np.pi]])
    np.testing.assert_allclose(body_to_world(p, np.array([1.0, 0.0])),
                               [[1.0, 3.0], [-1.0, 0.0]], atol=1e-15)
    # a unicycle moving forward at 2 m/s with heading pi/2 moves along +y
    np.testing.assert_allclose(velocity_body_to_world(p[0], np.array([2.0, 0.0])),
                               [0.0, 2.0], atol=1e-15)
    # many points per agent: (N, 1, 3) poses with (N, M, 2) points
    pts = np.arange(12.0).reshape(2, 3, 2)
    out = world_to_body(p[:, None], pts)
    assert out.shape == (2, 3, 2)
    np.testing.assert_allclose(out[1, 2], world_to_body(p[1], pts[1, 2]))
    np.testing.assert_allclose(rotate(np.pi / 2, np.array([1.0, 0.0])), [0.0, 1.0],
                               atol=1e-15)
    # relative pose of a leader 1 m ahead, seen from a follower facing +y
    rel = se2_relative(np.array([0.0, 0.0, np.pi / 2]), np.array([0.0, 1.0, np.pi / 2]))
    np.testing.assert_allclose(rel, [1.0, 0.0, 0.0], atol=1e-15)


@settings(max_examples=20)
@given(poses(1))
def test_single_pose_shapes(p):
    assert se2_compose(p[0], p[0]).shape == (3,)
    assert se2_to_matrix(p).shape == (1, 3, 3)
