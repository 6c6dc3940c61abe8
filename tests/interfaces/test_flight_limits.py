"""interfaces.flight.FlightLimits against hand-computed values."""

import numpy as np
import pytest

from avblocks.core.errors import ParameterError
from avblocks.interfaces.flight import FlightLimits


def test_speed_then_acceleration_then_fence():
    lim = FlightLimits(3, speed_max=1.0, accel_max=2.0, geofence=(-1, 1, -1, 1, 0, 2),
                       lookahead=1.0)
    v = np.array([[3.0, 4.0, 0.0], [0.0, 0.0, 0.1], [0.0, -0.05, 0.0]])
    prev = np.array([[0.6, 0.8, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    p = np.array([[0.0, 0.0, 1.0], [0.5, 0.0, 1.95], [0.0, -0.98, 1.0]])
    out = lim.shape(v, prev, 0.1, p)
    # 0: (3, 4) scaled to speed 1 -> (0.6, 0.8), equal to prev: no accel cut
    # 1: vz 0.1 within accel (0.2); the top face 0.05 m away in 1 s -> 0.05
    # 2: vy -0.05 toward the face 0.02 m away -> -0.02
    np.testing.assert_allclose(out, [[0.6, 0.8, 0.0], [0.0, 0.0, 0.05], [0.0, -0.02, 0.0]])
    # acceleration: from rest, 1 m/s wanted, 2 m/s^2 over 0.1 s -> 0.2 m/s
    p = np.zeros((3, 3)) + [0, 0, 1]
    out = lim.shape(np.array([[1.0, 0, 0]] * 3), np.zeros((3, 3)), 0.1, p)
    np.testing.assert_allclose(out[:, 0], 0.2)


def test_breaches_name_vehicles():
    lim = FlightLimits(3, geofence=(-1, 1, -1, 1), min_separation=0.5, fence_margin=0.2)
    p = np.array([[0.0, 0.0, 1.0], [0.3, 0.3, 1.0], [1.1, 0.0, 1.0]])
    assert lim.too_close(["a", "b", "c"], p) == ["a-b 0.42 m apart (min_separation 0.5 m)"]
    p[1] = [0.3, 0.0, 1.0]
    msgs = lim.breaches(["a", "b", "c"], p)
    assert msgs == ["a-b 0.30 m apart (min_separation 0.5 m)"]   # c within the margin
    p[2, 0] = 1.3
    assert "c at (1.30, 0.00, 1.00) is outside the geofence" in lim.breaches(["a", "b", "c"],
                                                                               p)[0]


def test_bad_limits():
    with pytest.raises(ParameterError, match="geofence"):
        FlightLimits(2, geofence=(1, 0, 0, 1))
    with pytest.raises(ParameterError, match="speed_max"):
        FlightLimits(2, speed_max=0.0)


def test_breaching_marks_the_vehicles_the_messages_name():
    lim = FlightLimits(4, geofence=(-1, 1, -1, 1), min_separation=0.5, fence_margin=0.2)
    p = np.array([[0.0, 0.0, 1.0], [0.3, 0.0, 1.0], [1.1, 0.0, 1.0], [-1.3, 0.5, 1.0]])
    assert lim.breaching(p).tolist() == [True, True, False, True]


def test_a_separation_just_under_the_minimum_never_reads_as_the_minimum():
    """0.7996 m under a 0.8 m minimum is shown rounded down (0.79), not as
    "0.80 m apart (min_separation 0.8 m)", which read as no breach at all."""
    lim = FlightLimits(2, min_separation=0.8)
    p = np.array([[0.0, 0.0, 1.0], [0.7996, 0.0, 1.0]])
    assert lim.too_close(["uav1", "uav2"], p) == ["uav1-uav2 0.79 m apart "
                                                  "(min_separation 0.8 m)"]
    p[1, 0] = 0.3                       # exact hundredths keep their digits
    assert lim.too_close(["uav1", "uav2"], p)[0].startswith("uav1-uav2 0.30 m apart")
