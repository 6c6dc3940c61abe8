"""Single and double integrators: exact polynomials and limits."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import avblocks as av
from avblocks.vehicles import DoubleIntegrator, SingleIntegrator

from ._util import run_const


@pytest.mark.parametrize("dim", [2, 3])
def test_single_integrator_linear_in_time(dim):
    gen = np.random.default_rng(dim)
    p0, v = gen.normal(size=(5, dim)), gen.normal(size=(5, dim))
    t, y = run_const(SingleIntegrator(p0, dim=dim), "velocity", v, 3.0, dt=0.1,
                     log=("position",))
    np.testing.assert_allclose(y["position"], p0 + v * t[:, None, None], atol=1e-12)


def test_single_integrator_speed_limit_keeps_direction():
    v = np.array([[3.0, 4.0, 0.0], [0.1, 0.0, 0.0]])
    t, y = run_const(SingleIntegrator(np.zeros((2, 3)), v_max=1.0), "velocity", v, 2.0,
                     log=("position",))
    np.testing.assert_allclose(y["position"][-1], [[1.2, 1.6, 0.0], [0.2, 0.0, 0.0]],
                               atol=1e-12)


def test_dim_is_checked():
    with pytest.raises(av.ParameterError):
        SingleIntegrator(np.zeros((2, 3)), dim=2)
    with pytest.raises(av.ParameterError):
        DoubleIntegrator(np.zeros((2, 4)))


@pytest.mark.parametrize("dim", [2, 3])
def test_double_integrator_quadratic_in_time(dim):
    gen = np.random.default_rng(10 + dim)
    p0, v0, a = (gen.normal(size=(4, dim)) for _ in range(3))
    blk = DoubleIntegrator(p0, velocity0=v0)
    t, y = run_const(blk, "accel", a, 4.0, dt=0.05, log=("position", "velocity"))
    T = t[:, None, None]
    np.testing.assert_allclose(y["position"], p0 + v0 * T + a * T**2 / 2, atol=1e-11)
    np.testing.assert_allclose(y["velocity"], v0 + a * T, atol=1e-12)


def test_double_integrator_force_input_and_drag():
    m, c = np.array([2.0, 0.5]), np.array([0.0, 0.4])
    F = np.array([[1.0, -2.0], [0.0, 0.0]])
    v0 = np.array([[0.0, 0.0], [1.0, 2.0]])
    blk = DoubleIntegrator(np.zeros((2, 2)), velocity0=v0, input="force", mass=m, drag=c)
    t, y = run_const(blk, "force", F, 3.0, log=("position", "velocity"))
    T = t[:, None]
    np.testing.assert_allclose(y["position"][:, 0], F[0] / m[0] * T**2 / 2, atol=1e-11)
    k = c[1] / m[1]
    np.testing.assert_allclose(y["velocity"][:, 1], v0[1] * np.exp(-k * T), atol=1e-8)
    np.testing.assert_allclose(y["position"][:, 1], v0[1] * (1 - np.exp(-k * T)) / k,
                               atol=1e-8)


def test_double_integrator_limits():
    blk = DoubleIntegrator(np.zeros((1, 3)), a_max=1.0, v_max=2.0)
    t, y = run_const(blk, "accel", [[0.0, 3.0, 4.0]], 5.0, log=("velocity",))
    speed = np.linalg.norm(y["velocity"][:, 0], axis=-1)
    # |a| clipped to 1: speed = t until the limit at t = 2, then held.
    np.testing.assert_allclose(speed[t <= 2.0], t[t <= 2.0], atol=1e-9)
    # the limit switches the acceleration off inside a step: overshoot <= a_max dt
    assert np.all(speed <= 2.0 + 1.0 * 0.01) and speed[-1] > 2.0 - 1e-6
    assert np.ptp(speed[t >= 2.1]) < 1e-12
    np.testing.assert_allclose(y["velocity"][-1, 0] / speed[-1], [0, 0.6, 0.8], atol=1e-9)


def test_double_integrator_matches_solve_ivp_with_drag_3d():
    c, m = 0.3, 1.7
    a = np.array([0.5, -0.2, 1.0])
    blk = DoubleIntegrator([[1.0, 2.0, 3.0]], velocity0=[0.1, 0.2, -0.3], mass=m, drag=c)
    t, y = run_const(blk, "accel", a[None], 3.0, log=("position",))

    def rhs(_t, s):
        return np.concatenate([s[3:], a - c / m * s[3:]])

    sol = solve_ivp(rhs, (0, 3), [1, 2, 3, 0.1, 0.2, -0.3], t_eval=t, rtol=1e-11, atol=1e-12)
    np.testing.assert_allclose(y["position"][:, 0], sol.y[:3].T, atol=1e-8)
