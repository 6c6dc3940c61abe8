"""Blimp: buoyancy, terminal speeds, and an independent solve_ivp model."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import avblocks as av
from avblocks.vehicles import Blimp

from ._util import angdiff, run_const

OUT = ("position", "velocity", "pose", "body_velocity")


def test_neutral_buoyancy_holds_altitude():
    p0 = np.array([[0.0, 0.0, 5.0], [1.0, 1.0, 2.0]])
    blk = Blimp(p0, body_velocity0=[[1.0, 0.2, 0.0, 0.3], [0.0, 0.0, 0.0, 0.0]])
    t, y = run_const(blk, "thrust", [[0.5, 0.0, 0.01], [0.0, 0.0, 0.0]], 10.0, log=OUT)
    np.testing.assert_allclose(y["position"][..., 2], np.broadcast_to(p0[:, 2], t.shape + (2,)),
                               atol=1e-12)
    np.testing.assert_allclose(y["position"][:, 1], np.broadcast_to(p0[1], (len(t), 3)),
                               atol=1e-12)
    assert np.ptp(y["position"][:, 0, 0]) > 1.0


@pytest.mark.parametrize("drag", ["linear", "quadratic"])
def test_constant_thrust_reaches_terminal_speed(drag):
    D = np.array([0.4, 0.6, 0.5, 0.05])
    f = np.array([[0.8, 0.0, 0.0], [0.2, 0.0, 0.0]])
    blk = Blimp(np.zeros((2, 3)), yaw0=[0.0, 1.0], drag=drag, drag_coeff=D)
    t, y = run_const(blk, "thrust", f, 100.0, dt=0.1, log=OUT)
    u_term = f[:, 0] / D[0] if drag == "linear" else np.sqrt(f[:, 0] / D[0])
    np.testing.assert_allclose(y["body_velocity"][-1, :, 0], u_term, rtol=1e-6)
    np.testing.assert_allclose(y["body_velocity"][-1, :, 1:], 0.0, atol=1e-12)
    speed = np.linalg.norm(y["velocity"][-1], axis=-1)
    np.testing.assert_allclose(speed, u_term, rtol=1e-6)
    # heading of the world velocity equals the yaw
    vel = y["velocity"][-1]
    assert angdiff(np.arctan2(vel[:, 1], vel[:, 0]), [0.0, 1.0]).max() < 1e-9


def test_linear_drag_surge_closed_form_and_net_lift():
    m, Xu, Zw, Du, Dw, L = 1.5, 0.3, 1.0, 0.4, 0.5, 0.2
    blk = Blimp([[0.0, 0.0, 1.0]], mass=m, added_mass=(Xu, 1.0, Zw, 0.1), drag="linear",
                drag_coeff=(Du, 0.6, Dw, 0.05), net_lift=L)
    t, y = run_const(blk, "thrust", [[0.3, 0.0, 0.0]], 8.0, log=OUT)
    u = 0.3 / Du * (1 - np.exp(-Du * t / (m + Xu)))
    w = L / Dw * (1 - np.exp(-Dw * t / (m + Zw)))
    np.testing.assert_allclose(y["body_velocity"][:, 0, 0], u, atol=1e-9)
    np.testing.assert_allclose(y["body_velocity"][:, 0, 2], w, atol=1e-9)
    z = 1.0 + L / Dw * (t - (m + Zw) / Dw * (1 - np.exp(-Dw * t / (m + Zw))))
    np.testing.assert_allclose(y["position"][:, 0, 2], z, atol=1e-8)


def test_thrust_limits():
    blk = Blimp(np.zeros((1, 3)), drag="linear", drag_coeff=(1.0, 1.0, 1.0, 1.0),
                thrust_max=(0.1, 0.2), torque_max=0.0)
    t, y = run_const(blk, "thrust", [[5.0, -5.0, 3.0]], 60.0, dt=0.05, log=OUT)
    np.testing.assert_allclose(y["body_velocity"][-1, 0], [0.1, 0.0, -0.2, 0.0], atol=1e-9)


@pytest.mark.parametrize("drag", ["linear", "quadratic"])
def test_matches_solve_ivp(drag):
    m, Jz = 2.0, 0.3
    ma = np.array([0.4, 1.2, 1.1, 0.15])
    D = np.array([0.3, 0.7, 0.6, 0.08])
    L = -0.1
    f = np.array([0.6, 0.05, 0.02])
    nu0 = [0.5, -0.2, 0.1, 0.4]
    blk = Blimp([[1.0, -1.0, 3.0]], yaw0=0.7, body_velocity0=nu0, mass=m, inertia=Jz,
                added_mass=ma, net_lift=L, drag=drag, drag_coeff=D)
    t, y = run_const(blk, "thrust", f[None], 10.0, dt=0.01, log=OUT)
    Mx, My, Mz, Iz = m + ma[0], m + ma[1], m + ma[2], Jz + ma[3]

    def d(s, k):
        return D[k] * s * (abs(s) if drag == "quadratic" else 1.0)

    def rhs(_t, s):
        x, yy, z, psi, u, v, w, r = s
        return [u * np.cos(psi) - v * np.sin(psi), u * np.sin(psi) + v * np.cos(psi), w, r,
                (f[0] + My * v * r - d(u, 0)) / Mx,
                (-Mx * u * r - d(v, 1)) / My,
                (f[1] + L - d(w, 2)) / Mz,
                (f[2] + (Mx - My) * u * v - d(r, 3)) / Iz]

    sol = solve_ivp(rhs, (0, 10), [1.0, -1.0, 3.0, 0.7, *nu0], t_eval=t, rtol=1e-11,
                    atol=1e-12, method="DOP853")
    np.testing.assert_allclose(y["position"][:, 0], sol.y[:3].T, atol=1e-7)
    assert angdiff(y["pose"][:, 0, 2], sol.y[3]).max() < 1e-8
    np.testing.assert_allclose(y["body_velocity"][:, 0], sol.y[4:].T, atol=1e-8)


def test_bad_drag_law():
    with pytest.raises(av.ParameterError):
        Blimp(np.zeros((1, 3)), drag="cubic")
