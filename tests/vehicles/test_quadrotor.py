"""Quadrotor: closed-form motions, energy balance, solve_ivp, velocity control."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import simpson, solve_ivp

import avblocks as av
from avblocks.vehicles import (
    Quadrotor,
    QuadrotorVelocityControl,
    SingleIntegrator,
    velocity_controlled_quadrotor,
)

from ._util import angdiff, run_const

G = 9.81
ALL = ("position", "velocity", "attitude", "rates", "pose")


def body_z(q):
    """Third column of the rotation matrix of q = (w, x, y, z) (written out)."""
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)], -1)


def test_hover_wrench_and_rotors():
    m = np.array([1.0, 0.5, 2.0])
    p0 = np.array([[0.0, 0.0, 1.0], [1.0, 2.0, 3.0], [-1.0, 0.0, 10.0]])
    t, y = run_const(Quadrotor(p0, mass=m), "wrench",
                     np.stack([m * G, 0 * m, 0 * m, 0 * m], -1), 5.0, log=ALL)
    np.testing.assert_allclose(y["position"], np.broadcast_to(p0, y["position"].shape),
                               atol=1e-12)
    for frame in ("x", "+"):
        blk = Quadrotor(p0, mass=m, input="rotors", frame=frame)
        _, yr = run_const(blk, "rotors", np.repeat(m[:, None] * G / 4, 4, 1), 5.0, log=ALL)
        # the mixer rounds sin(45 deg): torques ~1e-17 N m, drift ~1e-11 m in 5 s
        np.testing.assert_allclose(yr["position"], y["position"], atol=1e-9)
        np.testing.assert_allclose(yr["attitude"][-1], [[1, 0, 0, 0]] * 3, atol=1e-12)


def test_free_fall():
    v0 = np.array([[1.0, 0.0, 2.0], [0.0, -1.0, 0.0]])
    p0 = np.array([[0.0, 0.0, 100.0], [5.0, 5.0, 50.0]])
    t, y = run_const(Quadrotor(p0, velocity0=v0), "wrench", np.zeros((2, 4)), 3.0,
                     log=ALL)
    T = t[:, None, None]
    expect = p0 + v0 * T - np.array([0, 0, G]) * T**2 / 2
    np.testing.assert_allclose(y["position"], expect, atol=1e-10)


def test_pure_yaw_torque_closed_form():
    Jz, tau = np.array([0.02, 0.05]), np.array([0.01, -0.03])
    m = 1.0
    blk = Quadrotor(np.zeros((2, 3)), mass=m, inertia=np.stack([[0.01] * 2, [0.01] * 2, Jz], -1))
    w = np.stack([np.full(2, m * G), np.zeros(2), np.zeros(2), tau], -1)
    t, y = run_const(blk, "wrench", w, 4.0, log=ALL)
    T = t[:, None]
    np.testing.assert_allclose(y["rates"][..., 2], tau / Jz * T, atol=1e-10)
    yaw = tau / Jz * T**2 / 2
    assert angdiff(y["pose"][..., 2], yaw).max() < 1e-8
    q = y["attitude"]
    sign = np.sign(q[..., :1])
    np.testing.assert_allclose(q * sign, np.stack(
        [np.abs(np.cos(yaw / 2)), 0 * yaw, 0 * yaw, np.sin(yaw / 2) * np.sign(np.cos(yaw / 2))],
        -1), atol=1e-8)
    np.testing.assert_allclose(y["position"][..., 2], 0.0, atol=1e-10)


@pytest.mark.parametrize("frame", ["x", "+"])
def test_rotor_mixer_yaw_and_roll(frame):
    m, l, km, Jz = 1.0, 0.25, 0.02, 0.04
    blk = Quadrotor(np.zeros((1, 3)), mass=m, inertia=(0.01, 0.01, Jz), input="rotors",
                    frame=frame, arm_length=l, yaw_coeff=km)
    d = 0.1
    # rotors 2 and 4 spin clockwise: more thrust there gives +z reaction torque
    f = np.full(4, m * G / 4) + d * np.array([-1, 1, -1, 1])
    t, y = run_const(blk, "rotors", f[None], 1.0, log=ALL)
    np.testing.assert_allclose(y["rates"][:, 0, 2], 4 * d * km / Jz * t, atol=1e-10)
    np.testing.assert_allclose(y["rates"][:, 0, :2], 0.0, atol=1e-10)
    # roll from the mixer, computed from rotor positions independently
    ang = np.deg2rad([0, 90, 180, 270]) + (np.pi / 4 if frame == "x" else 0.0)
    f = np.full(4, m * G / 4) + 0.05 * np.sin(ang)
    wr = av.vehicles.rotors_to_wrench(f[None], np.array([l]), np.array([km]), frame)
    np.testing.assert_allclose(wr[0], [m * G, l * np.sum(np.sin(ang) * f),
                                       -l * np.sum(np.cos(ang) * f), 0.0], atol=1e-12)
    back = av.vehicles.wrench_to_rotors(wr, np.array([l]), np.array([km]), frame)
    np.testing.assert_allclose(back[0], f, atol=1e-12)


def test_energy_changes_only_by_work_of_inputs():
    m, J = 1.3, np.array([0.011, 0.017, 0.025])
    wrench = np.array([[12.0, 0.002, -0.003, 0.004]])
    blk = Quadrotor([[0.0, 0.0, 0.0]], velocity0=[0.5, -0.2, 0.1], rates0=[1.0, -2.0, 0.5],
                    mass=m, inertia=J)
    t, y = run_const(blk, "wrench", wrench, 2.0, dt=0.002, log=ALL)
    v, w, p, q = y["velocity"][:, 0], y["rates"][:, 0], y["position"][:, 0], y["attitude"][:, 0]
    E = 0.5 * m * np.sum(v**2, -1) + m * G * p[:, 2] + 0.5 * np.sum(J * w**2, -1)
    power = wrench[0, 0] * np.sum(body_z(q) * v, -1) + w @ wrench[0, 1:]
    work = np.array([simpson(power[: k + 1], x=t[: k + 1]) if k else 0.0
                     for k in range(0, len(t), 50)])
    np.testing.assert_allclose(E[::50] - E[0], work, atol=1e-7)
    assert np.ptp(E) > 1.0     # the test is not vacuous
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1.0, atol=1e-12)


def test_matches_solve_ivp_rotation_matrix_model():
    """Independent model: attitude as a rotation matrix, dR/dt = R [omega]x."""
    m, J, c = 0.9, np.array([0.008, 0.012, 0.02]), np.array([0.1, 0.2, 0.3])
    wrench = np.array([9.0, 0.001, 0.002, -0.001])
    blk = Quadrotor([[0.0, 1.0, 2.0]], velocity0=[0.3, 0.0, 0.0], rates0=[0.2, 0.1, -0.4],
                    mass=m, inertia=J, drag=c)
    t, y = run_const(blk, "wrench", wrench[None], 3.0, dt=0.005, log=ALL)

    def hat(w):
        return np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])

    def rhs(_t, s):
        v, R, w = s[3:6], s[6:15].reshape(3, 3), s[15:]
        dv = R[:, 2] * wrench[0] / m - np.array([0, 0, G]) - c * v / m
        dw = (wrench[1:] - np.cross(w, J * w)) / J
        return np.concatenate([v, dv, (R @ hat(w)).ravel(), dw])

    s0 = np.concatenate([[0, 1, 2, 0.3, 0, 0], np.eye(3).ravel(), [0.2, 0.1, -0.4]])
    sol = solve_ivp(rhs, (0, 3), s0, t_eval=t, rtol=1e-11, atol=1e-12, method="DOP853")
    np.testing.assert_allclose(y["position"][:, 0], sol.y[:3].T, atol=1e-7)
    np.testing.assert_allclose(y["rates"][:, 0], sol.y[15:].T, atol=1e-8)
    Rs = sol.y[6:15].T.reshape(-1, 3, 3)
    np.testing.assert_allclose(body_z(y["attitude"][:, 0]), Rs[:, :, 2], atol=1e-7)
    assert angdiff(y["pose"][:, 0, 2], np.arctan2(Rs[:, 1, 0], Rs[:, 0, 0])).max() < 1e-7


def test_quaternion_norm_is_restored():
    blk = Quadrotor(np.zeros((1, 3)), attitude0=[1, 0, 0, 0], quat_gain=2.0)
    x = blk.initial_state()
    x["attitude"] = x["attitude"] * 1.1
    dq = blk.derivative(0, x, {"wrench": np.zeros((1, 4))}, np)["attitude"]
    # d|q|^2/dt = 2 q.dq = 2 k (1 - |q|^2) |q|^2 < 0 when |q| > 1
    np.testing.assert_allclose(2 * np.sum(x["attitude"] * dq), 2 * 2.0 * (1 - 1.21) * 1.21)
    np.testing.assert_allclose(np.linalg.norm(blk.output(0, x, {}, np)["attitude"]), 1.0)


def _velocity_run(kind, ref, t_final=3.0):
    q = Quadrotor(np.zeros((len(ref), 3)), input=kind)
    d = av.Diagram()
    s = d.add(velocity_controlled_quadrotor(q), name="s")
    c = d.add(av.blocks.Constant(ref), name="c")
    d.connect(c.y, s.velocity)
    res = av.simulate(d, t_final, dt=0.005, log=["s.quad.velocity", "s.quad.pose"],
                      progress=False)
    return np.asarray(res.t), res["s.quad.velocity"], res["s.quad.pose"]


def settling_time(t, err, size, band=0.02):
    bad = np.nonzero(err > band * size)[0]
    return 0.0 if len(bad) == 0 else t[min(bad[-1] + 1, len(t) - 1)]


@pytest.mark.parametrize("kind", ["wrench", "rotors"])
def test_velocity_step_settling_time(kind):
    ref = np.array([[1.0, 0, 0], [0, 0, 1.0], [0.6, -0.8, 0.0]])
    t, v, pose = _velocity_run(kind, ref)
    err = np.linalg.norm(v - ref, axis=-1)
    ts = [settling_time(t, err[:, i], 1.0) for i in range(3)]
    # documented in QuadrotorVelocityControl: ~1.1 s horizontal, ~1.6 s vertical
    assert 0.9 < ts[0] < 1.3 and 0.9 < ts[2] < 1.3, ts
    assert 1.4 < ts[1] < 1.8, ts
    assert err[-1].max() < 1e-3                       # exp(-kv t) at t = 3 s
    assert np.abs(pose[..., 2]).max() < 0.05          # yaw held near its set-point 0


def test_holonomic_controller_flies_quadrotor_unchanged():
    """The same go-to-goal block drives a 3D SingleIntegrator and a quadrotor."""

    class GoTo(av.Block):
        def __init__(self, n, goal, gain=1.5, v_max=1.5):
            super().__init__()
            self.goal, self.gain, self.v_max = np.asarray(goal, float), gain, v_max
            self.declare_input("position", (n, 3))
            self.declare_output("velocity", (n, 3))

        def output(self, t, x, u, xp):
            v = self.gain * (self.goal - u["position"])
            nrm = xp.sqrt(xp.sum(v * v, axis=-1, keepdims=True))
            return {"velocity": v * xp.minimum(1.0, self.v_max / xp.maximum(nrm, 1e-12))}

    goal = np.array([[2.0, 1.0, 1.5], [-1.0, 0.5, 0.5]])
    finals = []
    for make in (lambda: SingleIntegrator(np.zeros((2, 3))),
                 lambda: velocity_controlled_quadrotor(Quadrotor(np.zeros((2, 3))))):
        d = av.Diagram()
        a = d.add(make(), name="agent")
        c = d.add(GoTo(2, goal), name="ctrl")
        d.connect(a.position, c.position)
        d.connect(c.velocity, a.velocity)
        res = av.simulate(d, 8.0, dt=0.02, log=[a.position], progress=False)
        finals.append(res[a.position][-1])
    np.testing.assert_allclose(finals[0], goal, atol=1e-3)
    np.testing.assert_allclose(finals[1], goal, atol=2e-3)


def test_controller_for_quadrotor_copies_parameters():
    q = Quadrotor(np.zeros((4, 3)), mass=[1, 2, 3, 4], input="rotors", frame="+")
    c = QuadrotorVelocityControl.for_quadrotor(q, kv=3.0)
    np.testing.assert_array_equal(c.mass, q.mass)
    assert c.out_kind == "rotors" and c.frame == "+" and c.kv == 3.0
    assert "rotors" in c.output_ports
