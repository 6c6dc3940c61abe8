"""interfaces.mavlink.frames against hand-written NED -> ENU truth: where
north, east and down go, what a heading means, what roll and pitch do to
the body axes (not the formulas of the module)."""

import numpy as np
import pytest

from avblocks.interfaces.mavlink import frames


def _rot(q):
    w, x, y, z = np.asarray(q, float) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def test_positions_and_velocities():
    # 1 m north, 2 m east, 3 m down of an origin at (10, 20, 30) ENU
    np.testing.assert_allclose(frames.position_to_world([1.0, 2.0, 3.0], [10, 20, 30]),
                               [12.0, 21.0, 27.0])
    np.testing.assert_allclose(frames.position_to_local([12.0, 21.0, 27.0], [10, 20, 30]),
                               [1.0, 2.0, 3.0])
    # climbing north-east at 1 m/s each way: NED (1, 1, -1)
    np.testing.assert_allclose(frames.ned_to_enu([1.0, 1.0, -1.0]), [1.0, 1.0, 1.0])
    np.testing.assert_allclose(frames.enu_to_ned([3.0, 0.0, 0.0]), [0.0, 3.0, 0.0])  # east


@pytest.mark.parametrize("heading, yaw", [(0.0, np.pi / 2), (np.pi / 2, 0.0),
                                          (-np.pi / 2, np.pi), (np.pi, -np.pi / 2),
                                          (np.pi / 4, np.pi / 4)])
def test_heading(heading, yaw):
    got = frames.yaw_to_enu(heading)
    assert np.isclose(np.cos(got), np.cos(yaw)) and np.isclose(np.sin(got), np.sin(yaw))
    back = frames.yaw_to_ned(got)
    assert np.isclose(np.cos(back), np.cos(heading)) and np.isclose(np.sin(back),
                                                                    np.sin(heading))


@pytest.mark.parametrize("heading", [0.0, 0.3, np.pi / 2, -2.0])
def test_attitude_heading_only(heading):
    q_ned = [np.cos(heading / 2), 0.0, 0.0, np.sin(heading / 2)]   # about down
    R = _rot(frames.quat_to_enu(q_ned))
    # forward points at the heading: north component cos, east component sin
    np.testing.assert_allclose(R[:, 0], [np.sin(heading), np.cos(heading), 0.0], atol=1e-12)
    np.testing.assert_allclose(R[:, 2], [0.0, 0.0, 1.0], atol=1e-12)     # up stays up


def test_attitude_roll_and_pitch_facing_north():
    phi = 0.3       # roll right wing down (NED/FRD convention)
    R = _rot(frames.quat_to_enu([np.cos(phi / 2), np.sin(phi / 2), 0, 0]))
    # the left wing (FLU +y) now points west and up
    np.testing.assert_allclose(R[:, 1], [-np.cos(phi), 0.0, np.sin(phi)], atol=1e-12)
    th = 0.2        # pitch nose up
    R = _rot(frames.quat_to_enu([np.cos(th / 2), 0, np.sin(th / 2), 0]))
    np.testing.assert_allclose(R[:, 0], [0.0, np.cos(th), np.sin(th)], atol=1e-12)


def test_round_trip_and_w_positive():
    rng = np.random.default_rng(0)
    q = rng.normal(size=(50, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    back = frames.quat_to_ned(frames.quat_to_enu(q))
    assert (frames.quat_to_enu(q)[:, 0] >= 0).all()
    np.testing.assert_allclose(np.abs(np.sum(back * q, axis=1)), 1.0, atol=1e-12)
