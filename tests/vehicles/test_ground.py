"""Ground vehicles against closed forms and independent ODE solutions."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import avblocks as av
from avblocks.vehicles import Ackermann, DiffDrive, Unicycle, Unicycle2

from ._util import angdiff, run_const


def arc(p0, v, w, t):
    """Closed-form pose of a unicycle at constant (v, w != 0)."""
    x0, y0, th0 = p0[:, 0], p0[:, 1], p0[:, 2]
    th = th0 + w * t[:, None]
    x = x0 + v / w * (np.sin(th) - np.sin(th0))
    y = y0 - v / w * (np.cos(th) - np.cos(th0))
    return x, y, th


P0 = np.array([[0.0, 0.0, 0.0], [1.0, -2.0, 2.5], [-3.0, 4.0, -1.0]])


def test_unicycle_arc_closed_form():
    cmd = np.array([[1.0, 0.5], [2.0, -0.3], [0.5, 2.0]])
    t, y = run_const(Unicycle(P0), "cmd", cmd, 10.0, dt=0.01)
    x, yy, th = arc(P0, cmd[:, 0], cmd[:, 1], t)
    pose = y["pose"]
    assert pose.shape == (len(t), 3, 3)
    np.testing.assert_allclose(pose[..., 0], x, atol=1e-8)
    np.testing.assert_allclose(pose[..., 1], yy, atol=1e-8)
    assert angdiff(pose[..., 2], th).max() < 1e-8
    assert np.all(pose[..., 2] <= np.pi) and np.all(pose[..., 2] > -np.pi)


def test_unicycle_saturation_limits_command():
    b = Unicycle(np.zeros((2, 3)), v_max=[1.0, 2.0], omega_max=0.5)
    t, y = run_const(b, "cmd", [[5.0, 0.0], [-5.0, 0.0]], 2.0)
    np.testing.assert_allclose(y["pose"][-1, :, 0], [2.0, -4.0], atol=1e-12)


def test_unicycle_saturated_output_is_opt_in():
    assert "cmd" not in Unicycle(np.zeros((1, 3))).feedthrough
    b = Unicycle(np.zeros((2, 3)), v_max=1.0, omega_max=1.0, saturation_output=True)
    assert "cmd" in b.feedthrough
    s = b.output(0, b.initial_state(), {"cmd": np.array([[2.0, 0.5], [0.5, -3.0]])},
                 np)["saturated"]
    np.testing.assert_array_equal(s, [[True, False], [False, True]])


def test_diffdrive_arc_closed_form():
    r, b = 0.1, 0.4
    wheels = np.array([[8.0, 12.0], [10.0, 14.0], [-5.0, 5.0]])
    t, y = run_const(DiffDrive(P0, wheel_radius=r, track_width=b), "wheels", wheels, 8.0)
    v = r * (wheels[:, 0] + wheels[:, 1]) / 2
    w = r * (wheels[:, 1] - wheels[:, 0]) / b
    x, yy, th = arc(P0, v, w, t)
    np.testing.assert_allclose(y["pose"][..., 0], x, atol=1e-8)
    np.testing.assert_allclose(y["pose"][..., 1], yy, atol=1e-8)
    assert angdiff(y["pose"][..., 2], th).max() < 1e-8


def test_diffdrive_equals_unicycle_under_wheel_mapping():
    gen = np.random.default_rng(1)
    n = 20
    p0 = gen.normal(size=(n, 3))
    r = gen.uniform(0.03, 0.1, n)
    b = gen.uniform(0.2, 0.6, n)
    cmd = np.stack([gen.uniform(-1, 1, n), gen.uniform(-2, 2, n)], axis=-1)
    # independent inverse mapping: omega_R - omega_L = w b / r, sum = 2 v / r
    wl = (cmd[:, 0] - cmd[:, 1] * b / 2) / r
    wr = (cmd[:, 0] + cmd[:, 1] * b / 2) / r
    _, yd = run_const(DiffDrive(p0, wheel_radius=r, track_width=b), "wheels",
                      np.stack([wl, wr], -1), 5.0)
    _, yu = run_const(Unicycle(p0), "cmd", cmd, 5.0)
    np.testing.assert_allclose(yd["pose"][..., :2], yu["pose"][..., :2], atol=1e-10)
    assert angdiff(yd["pose"][..., 2], yu["pose"][..., 2]).max() < 1e-10
    np.testing.assert_allclose(av.vehicles.twist_to_wheels(cmd, r, b), np.stack([wl, wr], -1))


def test_diffdrive_wheel_speed_limit():
    b = DiffDrive(np.zeros((1, 3)), wheel_radius=0.1, track_width=0.5, wheel_speed_max=5.0)
    _, y = run_const(b, "wheels", [[20.0, 20.0]], 2.0)
    np.testing.assert_allclose(y["pose"][-1, 0], [1.0, 0.0, 0.0], atol=1e-12)


def test_unicycle2_constant_force_closed_form():
    m, J = np.array([2.0, 0.5]), np.array([0.3, 1.0])
    f = np.array([1.0, -0.4])
    v0, w0 = np.array([0.5, 1.0]), np.array([0.7, -1.2])
    p0 = np.array([[0.0, 0.0, 0.3], [2.0, 1.0, -2.0]])
    blk = Unicycle2(p0, twist0=np.stack([v0, w0], -1), mass=m, inertia=J)
    t, y = run_const(blk, "wrench", np.stack([f, [0.0, 0.0]], -1), 6.0,
                     log=("pose", "twist"))
    a = f / m
    T = t[:, None]
    th0 = p0[:, 2]
    th = th0 + w0 * T
    x = p0[:, 0] + v0 * (np.sin(th) - np.sin(th0)) / w0 + a * (
        T * np.sin(th) / w0 + (np.cos(th) - np.cos(th0)) / w0**2)
    yy = p0[:, 1] - v0 * (np.cos(th) - np.cos(th0)) / w0 + a * (
        -T * np.cos(th) / w0 + (np.sin(th) - np.sin(th0)) / w0**2)
    np.testing.assert_allclose(y["twist"][..., 0], v0 + a * T, atol=1e-10)
    np.testing.assert_allclose(y["twist"][..., 1], np.broadcast_to(w0, th.shape), atol=1e-12)
    np.testing.assert_allclose(y["pose"][..., 0], x, atol=1e-7)
    np.testing.assert_allclose(y["pose"][..., 1], yy, atol=1e-7)
    assert angdiff(y["pose"][..., 2], th).max() < 1e-9


def test_unicycle2_torque_and_damping_closed_form_twist():
    m, J, bv, bw = 1.5, 0.4, 0.6, 0.2
    f, tau = 0.9, -0.3
    blk = Unicycle2(np.zeros((1, 3)), mass=m, inertia=J, lin_damping=bv, ang_damping=bw)
    t, y = run_const(blk, "wrench", [[f, tau]], 10.0, log=("pose", "twist"))
    v = f / bv * (1 - np.exp(-bv * t / m))
    w = tau / bw * (1 - np.exp(-bw * t / J))
    th = tau / bw * (t - J / bw * (1 - np.exp(-bw * t / J)))
    np.testing.assert_allclose(y["twist"][:, 0, 0], v, atol=1e-9)
    np.testing.assert_allclose(y["twist"][:, 0, 1], w, atol=1e-9)
    assert angdiff(y["pose"][:, 0, 2], th).max() < 1e-8


def test_unicycle2_matches_solve_ivp_and_limits():
    m, J, bv, bw = 1.2, 0.3, 0.1, 0.05
    u = np.array([3.0, 0.8])             # f clipped to 2.0
    blk = Unicycle2([[1.0, 2.0, 0.5]], twist0=[0.2, -0.5], mass=m, inertia=J,
                    lin_damping=bv, ang_damping=bw, f_max=2.0, tau_max=1.0)
    t, y = run_const(blk, "wrench", u[None], 5.0, log=("pose", "twist"))

    def rhs(_t, s):
        x, yy, th, v, w = s
        return [v * np.cos(th), v * np.sin(th), w, (2.0 - bv * v) / m, (0.8 - bw * w) / J]

    sol = solve_ivp(rhs, (0, 5), [1.0, 2.0, 0.5, 0.2, -0.5], t_eval=t, rtol=1e-11, atol=1e-12)
    np.testing.assert_allclose(y["pose"][:, 0, :2], sol.y[:2].T, atol=1e-7)
    assert angdiff(y["pose"][:, 0, 2], sol.y[2]).max() < 1e-7
    np.testing.assert_allclose(y["twist"][:, 0], sol.y[3:].T, atol=1e-8)


@pytest.mark.parametrize("solver", ["rk4", "RK45"])
def test_ackermann_circle(solver):
    L = np.array([2.5, 1.0, 3.0])
    delta = np.array([0.3, -0.5, 0.1])
    v = np.array([2.0, 1.0, -1.5])
    blk = Ackermann(P0, wheelbase=L)
    t, y = run_const(blk, "cmd", np.stack([v, delta], -1), 8.0, dt=0.02, solver=solver)
    R = L / np.tan(delta)
    cx = P0[:, 0] - R * np.sin(P0[:, 2])
    cy = P0[:, 1] + R * np.cos(P0[:, 2])
    pose = y["pose"]
    dist = np.hypot(pose[..., 0] - cx, pose[..., 1] - cy)
    tol = 1e-8 if solver == "rk4" else 1e-4
    np.testing.assert_allclose(dist, np.broadcast_to(np.abs(R), dist.shape), atol=tol)
    th = P0[:, 2] + v * np.tan(delta) / L * t[:, None]
    assert angdiff(pose[..., 2], th).max() < tol


def test_ackermann_limits():
    blk = Ackermann(np.zeros((1, 3)), wheelbase=2.0, v_max=1.0, delta_max=0.4)
    t, y = run_const(blk, "cmd", [[3.0, 1.0]], 3.0)
    np.testing.assert_allclose(y["pose"][-1, 0, 2], np.tan(0.4) / 2.0 * 3.0, atol=1e-9)
    with pytest.raises(av.ParameterError):
        Ackermann(np.zeros((1, 3)), delta_max=2.0)


def test_ackermann_steering_lag_matches_solve_ivp():
    L, tau, dc = 2.0, 0.5, 0.35
    blk = Ackermann([[0.0, 1.0, 0.2]], wheelbase=L, steer_tau=tau)
    assert "steer" in blk.output_ports
    t, y = run_const(blk, "cmd", [[1.5, dc]], 4.0, log=("pose", "steer"))
    np.testing.assert_allclose(y["steer"][:, 0], dc * (1 - np.exp(-t / tau)), atol=1e-9)

    def rhs(_t, s):
        x, yy, th, d = s
        return [1.5 * np.cos(th), 1.5 * np.sin(th), 1.5 * np.tan(d) / L, (dc - d) / tau]

    sol = solve_ivp(rhs, (0, 4), [0.0, 1.0, 0.2, 0.0], t_eval=t, rtol=1e-11, atol=1e-12)
    np.testing.assert_allclose(y["pose"][:, 0, :2], sol.y[:2].T, atol=1e-7)
    assert angdiff(y["pose"][:, 0, 2], sol.y[2]).max() < 1e-7


def test_ackermann_steer_rate_limit():
    blk = Ackermann(np.zeros((1, 3)), steer_tau=0.01, steer_rate_max=0.1, delta_max=0.5)
    t, y = run_const(blk, "cmd", [[1.0, 0.5]], 2.0, log=("steer",))
    np.testing.assert_allclose(y["steer"][:, 0], 0.1 * t, atol=1e-9)


def test_wrapped_pose_numpy_path_equals_wrap_angle_bit_for_bit():
    """The NumPy fast path of the unicycle's pose output: the state itself
    when every heading is already in (-pi, pi], otherwise x and y untouched
    and the heading exactly ``wrap_angle`` of it (the JAX path's formula)."""
    from avblocks.utility.angles import wrap_angle
    from avblocks.vehicles.unicycle import wrapped_pose

    rng = np.random.default_rng(3)
    inside = np.column_stack([rng.normal(size=(50, 2)),
                              rng.uniform(-np.pi, np.pi, 50)])
    inside[0, 2] = np.pi                    # pi itself stays: (-pi, pi]
    assert wrapped_pose(inside) is inside
    for th in (rng.uniform(-40, 40, 200),
               np.array([-np.pi, 3 * np.pi, -3 * np.pi, 1e6, np.nextafter(np.pi, 4)])):
        p = np.column_stack([rng.normal(size=(th.size, 2)), th])
        before = p.copy()
        w = wrapped_pose(p)
        np.testing.assert_array_equal(p, before)           # input not written
        np.testing.assert_array_equal(w[:, :2], p[:, :2])
        np.testing.assert_array_equal(w[:, 2], wrap_angle(th))
        assert np.all((w[:, 2] > -np.pi) & (w[:, 2] <= np.pi))
    nan = inside.copy()
    nan[3, 2] = np.nan
    w = wrapped_pose(nan)
    assert np.isnan(w[3, 2])
    np.testing.assert_array_equal(np.delete(w, 3, 0), np.delete(nan, 3, 0))
