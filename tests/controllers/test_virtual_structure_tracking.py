"""The blocks of the drone case studies, against independent truth:
FormationReference (its velocity is the time derivative of its position,
its plan starts at the start and ends in the slots around a centre on the
circle), ReferenceTracker (the saturated law by hand), TrackingController
(a plain-Python alpha-beta filter; zero steady lag on a constant-velocity
target), VelocityControlledQuadrotor (the same run as the subsystem the
function builds)."""

from __future__ import annotations

import numpy as np
import pytest

import avblocks as av
from avblocks.controllers import FormationReference, ReferenceTracker, TrackingController
from avblocks.core.check import check_block


def _ref(n=4):
    rng = np.random.default_rng(3)
    start = rng.uniform(-2, 2, (n, 3))
    offsets = rng.uniform(-1, 1, (n, 3))
    return FormationReference(start, offsets, path_radius=1.5, period=20.0, gather=5.0,
                              climb=0.4), start, offsets


def test_formation_reference_velocity_is_the_derivative_of_its_position():
    ref, _, _ = _ref()
    h = 1e-6
    for t in (0.3, 2.5, 4.9, 5.2, 7.0, 13.3):
        p1 = ref.output(t - h, {}, {}, np)["position"]
        p2 = ref.output(t + h, {}, {}, np)["position"]
        v = ref.output(t, {}, {}, np)["velocity"]
        np.testing.assert_allclose(v, (p2 - p1) / (2 * h), atol=1e-6)


def test_formation_reference_starts_at_the_start_and_flies_the_slots_on_the_circle():
    ref, start, offsets = _ref()
    np.testing.assert_allclose(ref.output(0.0, {}, {}, np)["position"], start)
    c0 = start.mean(axis=0)
    for t in (5.0, 10.0, 25.0):                 # after gather: slots around the centre
        T = t - 5.0
        w = 2 * np.pi / 20.0
        centre = c0 + [1.5 * np.sin(w * T), 1.5 * (1 - np.cos(w * T)), 0.4 * np.sin(w * T)]
        np.testing.assert_allclose(ref.output(t, {}, {}, np)["position"], centre + offsets,
                                   atol=1e-12)
    # a full period later the formation is back where it formed
    np.testing.assert_allclose(ref.output(25.0, {}, {}, np)["position"],
                               ref.output(5.0, {}, {}, np)["position"], atol=1e-12)


def test_reference_tracker_law_by_hand():
    trk = ReferenceTracker(3, gain=2.0, v_max=1.0)
    p = np.array([[0.0, 0, 0], [1, 1, 1], [5, 0, 0]])
    pr = np.array([[0.1, 0, 0], [1, 1, 1.2], [0, 0, 0]])
    vr = np.array([[0.0, 0.2, 0], [0, 0, 0], [0, 0, 0]])
    v = trk.output(0, {}, {"position": p, "ref_position": pr, "ref_velocity": vr},
                   np)["velocity"]
    np.testing.assert_allclose(v[0], [0.2, 0.2, 0.0])            # under the limit
    np.testing.assert_allclose(v[1], [0.0, 0.0, 0.4])
    np.testing.assert_allclose(v[2], [-1.0, 0.0, 0.0])           # clipped to v_max


@pytest.mark.parametrize("make", [lambda n: ReferenceTracker(n),
                                  lambda n: FormationReference(np.zeros((n, 3)),
                                                               np.ones((n, 3))),
                                  lambda n: TrackingController(n, 0.1)])
def test_blocks_pass_the_conformance_checker(make):
    check_block(make)


def _alpha_beta(zs, valid, T, alpha, beta):
    """The filter written out, one agent, plain Python floats."""
    p = [0.0, 0.0]
    v = [0.0, 0.0]
    seen = False
    out = []
    for z, ok in zip(zs, valid):
        pp = [p[0] + T * v[0], p[1] + T * v[1]]
        if ok and not seen:
            p, v = [z[0], z[1]], [0.0, 0.0]
        elif ok:
            r = [z[0] - pp[0], z[1] - pp[1]]
            p = [pp[0] + alpha * r[0], pp[1] + alpha * r[1]]
            v = [v[0] + beta / T * r[0], v[1] + beta / T * r[1]]
        else:
            p = pp
        seen = seen or ok
        out.append(p + v)
    return np.array(out)


def _run_controller(target, valid, T=0.1, start=(5.0, -3.0, 4.0)):
    """TrackingController fed the measurements ``target`` (K, 2) with a
    follower held at ``start``; the logged estimates (K, 4)."""
    d = av.Diagram()
    k = len(target)
    z = np.column_stack([target, np.zeros(k)])
    t_grid = np.arange(k) * T
    meas = d.add(av.blocks.Function(
        lambda t, xp: {"point": z[min(int(round(t / T)), k - 1)][None],
                       "valid": np.array([valid[min(int(round(t / T)), k - 1)]])},
        inputs={}, outputs={"point": (1, 3), "valid": av.Port("valid", (1,), "bool")},
        period=T),
        name="meas")
    pos = d.add(av.blocks.Constant(np.array([start])), name="pos")
    ctl = d.add(TrackingController(1, T, k_p=1.0, altitude=4.0), name="ctl")
    d.connect(meas.point, ctl.point)
    d.connect(meas.valid, ctl.valid)
    d.connect(pos.y, ctl.position)
    res = av.simulate(d, t_final=t_grid[-1], dt=T, solver="euler", log=["ctl.estimate",
                                                                         "ctl.velocity"])
    return res


def test_tracking_controller_is_the_alpha_beta_filter_and_its_velocity_law():
    T, k = 0.1, 40
    rng = np.random.default_rng(0)
    t = np.arange(k) * T
    target = np.column_stack([1.0 + 0.8 * t, -0.5 + 0.3 * t]) + rng.normal(0, 0.02, (k, 2))
    valid = rng.uniform(size=k) > 0.2
    valid[:3] = False                              # nothing seen at first
    res = _run_controller(target, valid, T)
    est = np.asarray(res["ctl.estimate"])[:, 0]
    np.testing.assert_allclose(est, _alpha_beta(target, valid, T, 0.6, 0.15), atol=1e-12)
    vel = np.asarray(res["ctl.velocity"])[:, 0]
    # the law: v_xy = v_hat + k_p (p_hat - x), clipped to 3 m/s; v_z = k_z (4 - 4) = 0
    raw = est[:, 2:] + 1.0 * (est[:, :2] - [5.0, -3.0])
    scale = np.minimum(1.0, 3.0 / np.linalg.norm(raw, axis=1))[:, None]
    np.testing.assert_allclose(vel[:, :2], raw * scale, atol=1e-12)
    np.testing.assert_allclose(vel[:, 2], 0.0, atol=1e-15)


def test_tracking_controller_has_no_steady_lag_on_a_constant_velocity_target():
    """An alpha-beta tracker follows a constant-velocity target with zero
    steady-state error (Kalata 1984): estimates converge to the true
    position and velocity."""
    T, k = 0.1, 300
    t = np.arange(k) * T
    target = np.column_stack([0.8 * t, -0.4 * t + 2.0])
    res = _run_controller(target, np.ones(k, bool), T)
    est = np.asarray(res["ctl.estimate"])[-1, 0]
    np.testing.assert_allclose(est[:2], target[-1], atol=1e-6)
    np.testing.assert_allclose(est[2:], [0.8, -0.4], atol=1e-6)


def test_tracking_controller_refuses_bad_gains_by_name():
    with pytest.raises(av.ParameterError, match="alpha"):
        TrackingController(1, 0.1, alpha=1.5)
    with pytest.raises(av.ParameterError, match="period"):
        TrackingController(1, 0.0)
    with pytest.raises(av.ParameterError, match="start"):
        TrackingController(2, 0.1, start=[[0, 0]])


def test_velocity_controlled_quadrotor_class_is_the_functions_subsystem():
    p0 = np.array([[0.0, 0.0, 1.0], [2.0, 1.0, 1.5]])
    runs = []
    for fleet in (av.vehicles.VelocityControlledQuadrotor(p0, kv=3.0),
                  av.vehicles.velocity_controlled_quadrotor(av.vehicles.Quadrotor(p0),
                                                            kv=3.0)):
        d = av.Diagram()
        f = d.add(fleet, name="fleet")
        c = d.add(av.blocks.Constant(np.array([[1.0, 0.0, 0.2], [0.0, -0.5, 0.0]])),
                  name="v")
        d.connect(c.y, f.velocity)
        runs.append(av.simulate(d, t_final=2.0, dt=0.005, log=["fleet.position",
                                                               "fleet.attitude"]))
    for k in ("fleet.position", "fleet.attitude"):
        np.testing.assert_array_equal(runs[0][k], runs[1][k])
    # and it flies: after 2 s (6 time constants 1/kv) at the commanded velocity
    p = np.asarray(runs[0]["fleet.position"])
    v = (p[-1] - p[-41]) / 0.2
    np.testing.assert_allclose(v, [[1.0, 0.0, 0.2], [0.0, -0.5, 0.0]], atol=0.02)
