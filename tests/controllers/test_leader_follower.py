"""LeaderFollower against eqs. (2)-(5) written out independently, and in closed loop."""

import math

import numpy as np
import pytest

import avblocks as av
from avblocks.controllers import LeaderFollower, leader_follower_law, references
from avblocks.controllers.leader_follower import tree_levels


def _wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def paper_cmd(pf, pl, c0, l_ref, a_ref, d, kl, ka):
    """Eqs. (2)-(5) for one follower, by explicit matrices (D[1,1] = -1)."""
    xd = pf[0] + d * math.cos(pf[2])
    yd = pf[1] + d * math.sin(pf[2])
    l = math.hypot(pl[0] - xd, pl[1] - yd)
    zeta = math.atan2(pl[1] - yd, pl[0] - xd)
    alpha = _wrap(zeta - pl[2])
    beta = _wrap(zeta - pf[2])
    u = np.array([kl * (l_ref - l), ka * _wrap(a_ref - alpha)])
    finv = np.array([[-math.cos(beta), l * math.sin(beta)],
                     [-math.sin(beta) / d, -l * math.cos(beta) / d]])
    # F from differentiating (2): ds/dt = F [v, w] + D [v0, w0]
    f = np.array([[-math.cos(beta), -d * math.sin(beta)],
                  [math.sin(beta) / l, -d * math.cos(beta) / l]])
    assert np.allclose(finv, np.linalg.inv(f), atol=1e-9)
    dmat = np.array([[math.cos(alpha), 0.0], [-math.sin(alpha) / l, -1.0]])
    return finv @ (u - dmat @ np.asarray(c0))


def test_law_matches_equations_random_states():
    rng = np.random.default_rng(1)
    n = 40
    pf = np.column_stack([rng.uniform(-5, 5, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    pl = np.column_stack([rng.uniform(-5, 5, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    c0 = rng.uniform(-1, 1, (n, 2))
    l_ref, a_ref = rng.uniform(0.5, 2, n), rng.uniform(-2, 2, n)
    kl, ka, d = rng.uniform(0.5, 3, n), rng.uniform(0.5, 3, n), 0.3
    got = leader_follower_law(pf, pl, c0, l_ref, a_ref, d, kl, ka, l_min=1e-9)
    want = np.array([paper_cmd(pf[i], pl[i], c0[i], l_ref[i], a_ref[i], d, kl[i], ka[i])
                     for i in range(n)])
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    # and through the block: agent i+n follows agent i
    lf = LeaderFollower(np.r_[-np.ones(n, int), np.arange(n)],
                        np.r_[np.zeros(n), l_ref], np.r_[np.zeros(n), a_ref],
                        d=d, k_l=np.r_[np.ones(n), kl], k_alpha=np.r_[np.ones(n), ka],
                        l_min=1e-9)
    out = lf.output(0, {}, {"pose": np.r_[pl, pf], "cmd_in": np.r_[c0, c0 * 0 + 7]}, np)
    np.testing.assert_allclose(out["cmd"][:n], c0, atol=0)
    np.testing.assert_allclose(out["cmd"][n:], want, rtol=0, atol=1e-12)


def test_kinematics_finite_differences():
    """ds/dt of (2) along the unicycle motion equals u under the law (checks D[1,1] = -1)."""
    rng = np.random.default_rng(2)
    n, d, h = 20, 0.2, 1e-6
    pf = np.column_stack([rng.uniform(-3, 3, (n, 2)), rng.uniform(-3, 3, n)])
    pl = np.column_stack([rng.uniform(-3, 3, (n, 2)), rng.uniform(-3, 3, n)])
    c0 = rng.uniform(-1, 1, (n, 2))
    l_ref, a_ref, k = 1.0, 0.4, 1.5
    cmd = leader_follower_law(pf, pl, c0, l_ref, a_ref, d, k, k)

    def s_of(f, l):
        xd, yd = f[:, 0] + d * np.cos(f[:, 2]), f[:, 1] + d * np.sin(f[:, 2])
        dx, dy = l[:, 0] - xd, l[:, 1] - yd
        return np.hypot(dx, dy), np.arctan2(dy, dx) - l[:, 2]

    rhs = av.vehicles.unicycle.unicycle_rhs
    lp, ap = s_of(pf + h * rhs(pf, cmd), pl + h * rhs(pl, c0))
    lm, am = s_of(pf - h * rhs(pf, cmd), pl - h * rhs(pl, c0))
    l0, a0 = s_of(pf, pl)
    np.testing.assert_allclose((lp - lm) / (2 * h), k * (l_ref - l0), atol=1e-6)
    np.testing.assert_allclose(_wrap(ap - am) / (2 * h), k * _wrap(a_ref - a0), atol=1e-6)


def _pair_diagram(pose0, cmd0, lf):
    d = av.Diagram()
    veh = d.add(av.vehicles.Unicycle(pose0=pose0), name="veh")
    c = d.add(av.blocks.Constant(cmd0), name="c")
    ctl = d.add(lf, name="lf")
    d.connect(veh.pose, ctl.pose)
    d.connect(c.y, ctl.cmd_in)
    d.connect(ctl.cmd, veh.cmd)
    return d, veh, ctl


def test_follower_behind_circling_leader_converges_at_predicted_rate():
    kl, ka, l_ref, a_ref = 1.0, 2.0, 1.5, 0.3
    lf = LeaderFollower([-1, 0], l_ref, a_ref, d=0.2, k_l=kl, k_alpha=ka)
    pose0 = np.array([[0.0, 0.0, 0.0], [-3.0, 1.0, 0.2]])
    d, veh, ctl = _pair_diagram(pose0, [[1.0, 0.25], [0.0, 0.0]], lf)
    e0 = lf.output(0, {}, {"pose": pose0, "cmd_in": np.zeros((2, 2))}, np)["error"][1]
    t_l = math.log(abs(e0[0]) / (0.01 * l_ref)) / kl
    t_a = math.log(abs(e0[1]) / (0.01 * abs(a_ref))) / ka
    t_pred = max(t_l, t_a)
    res = av.simulate(d, round(1.2 * t_pred, 2), dt=0.01, log=[ctl.error, veh.pose])
    err, t = res[ctl.error][:, 1], res.t
    # exponential decay as predicted, and within 1% once the predicted time passed
    np.testing.assert_allclose(err[:, 0], e0[0] * np.exp(-kl * t), atol=1e-4)
    np.testing.assert_allclose(err[:, 1], e0[1] * np.exp(-ka * t), atol=1e-4)
    after = t >= t_pred
    assert np.all(np.abs(err[after, 0]) <= 0.01 * l_ref)
    assert np.all(np.abs(err[after, 1]) <= 0.01 * abs(a_ref))
    assert np.abs(err[t < 0.8 * t_pred, 0]).max() > 0.01 * l_ref
    # the leader really drove a circle (radius v/omega = 4)
    p = res[veh.pose][:, 0, :2]
    np.testing.assert_allclose(np.hypot(p[:, 0], p[:, 1] - 4.0), 4.0, atol=1e-6)


def test_three_level_cascade_holds_shape():
    # leader -> 4 -> 8: level 1 in a wedge/line, each level-1 agent leads two
    off = np.array([[0, 0],
                    [-1, 1], [-1, -1], [-1, 2.5], [-1, -2.5],
                    [-2, 1.5], [-2, 0.5], [-2, -1.5], [-2, -0.5],
                    [-2, 3], [-2, 2], [-2, -3], [-2, -2]], float)
    leader = np.array([-1, 0, 0, 0, 0, 1, 1, 2, 2, 3, 3, 4, 4])
    assert tree_levels(leader).tolist() == [0] + [1] * 4 + [2] * 8
    dd = 0.2
    l_ref, a_ref = references(off, leader, dd)
    lf = LeaderFollower(leader, l_ref, a_ref, d=dd, k_l=1.5, k_alpha=1.5)
    rng = np.random.default_rng(3)
    pose0 = np.column_stack([off + rng.normal(0, 0.15, off.shape),
                             rng.normal(0, 0.2, 13)])
    cmd0 = np.zeros((13, 2))
    cmd0[0] = [0.8, 0.0]
    d, veh, ctl = _pair_diagram(pose0, cmd0, lf)
    res = av.simulate(d, 25.0, dt=0.02, log=[ctl.error, veh.pose])
    assert np.abs(res[ctl.error][-1]).max() < 1e-4
    pose = res[veh.pose][-1]
    rel = pose[:, :2] - pose[0, :2]
    c, s = math.cos(pose[0, 2]), math.sin(pose[0, 2])
    body = np.column_stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]])
    np.testing.assert_allclose(body, off, atol=0.02)
    np.testing.assert_allclose(_wrap(pose[:, 2] - pose[0, 2]), 0, atol=0.02)


def test_bad_definitions_rejected():
    with pytest.raises(av.ParameterError, match="cycle"):
        LeaderFollower([-1, 2, 1], 1.0, 0.0)
    with pytest.raises(av.ParameterError, match="itself"):
        LeaderFollower([-1, 1], 1.0, 0.0)
    with pytest.raises(av.ParameterError):
        LeaderFollower([-1, 5], 1.0, 0.0)
    with pytest.raises(av.ParameterError):
        LeaderFollower([-1, 0], 1.0, 0.0, d=0.0)


def test_long_chain_and_singular_distance():
    n = 50
    lf = LeaderFollower(np.arange(-1, n - 1), 1.0, 0.0, d=0.1)
    # follower points (0.1 ahead) exactly l = 1 behind their leaders: zero error
    pose = np.column_stack([-np.arange(n) * 1.1, np.zeros(n), np.zeros(n)])
    cmd_in = np.zeros((n, 2))
    cmd_in[0] = [1.0, 0.0]
    out = lf.output(0, {}, {"pose": pose, "cmd_in": cmd_in}, np)
    np.testing.assert_allclose(out["cmd"], cmd_in[[0] * n], atol=1e-12)
    # l = 0: finite output (clamped), zeta = 0
    same = np.array([[0.0, 0, 0.3], [-0.1 * math.cos(1.0), -0.1 * math.sin(1.0), 1.0]])
    c = LeaderFollower([-1, 0], 1.0, 0.5).output(
        0, {}, {"pose": same, "cmd_in": np.ones((2, 2))}, np)["cmd"]
    assert np.all(np.isfinite(c))
