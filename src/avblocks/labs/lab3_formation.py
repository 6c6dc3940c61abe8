"""Lab 3's checks: leader following (AVLib paper eqs. 2-5, corrected sign).

Independent truth: the law written here from the equations (F^-1 of (5)
and D, matrix products per agent); the library's
``controllers.leader_follower_law``; finite differences of (2) along the
exact motion, which must give ``dl/dt = K_l (l_ref - l)`` and
``dalpha/dt = K_alpha (alpha_ref - alpha)``; the closed loop behind a
turning leader, whose distance error decays exactly as ``exp(-K_l t)``.

With a seed (``--seed``, ``--student``) the configurations, references,
off-axis distance, gains and the leader's command are drawn per student.
"""

from __future__ import annotations

import numpy as np

from ..blocks import Constant
from ..controllers import leader_follower_law
from ..core.diagram import Diagram
from ..core.frontend import simulate
from ..vehicles import Unicycle
from .grading import Failed, Lab, compare, expect_shape


def _wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def _s(pose, pose_l, d):
    xd = pose[:, 0] + d * np.cos(pose[:, 2])
    yd = pose[:, 1] + d * np.sin(pose[:, 2])
    zeta = np.arctan2(pose_l[:, 1] - yd, pose_l[:, 0] - xd)
    return np.hypot(pose_l[:, 0] - xd, pose_l[:, 1] - yd), _wrap(zeta - pose_l[:, 2]), \
        _wrap(zeta - pose[:, 2])


def _truth(pose, pose_l, cmd_l, l_ref, a_ref, d, kl, ka):
    l, alpha, beta = _s(pose, pose_l, d)
    u = np.column_stack([kl * (l_ref - l), ka * _wrap(a_ref - alpha)])
    out = np.empty((len(pose), 2))
    for i in range(len(pose)):          # per agent, from the printed matrices
        finv = np.array([[-np.cos(beta[i]), l[i] * np.sin(beta[i])],
                         [-np.sin(beta[i]) / d, -l[i] * np.cos(beta[i]) / d]])
        dmat = np.array([[np.cos(alpha[i]), 0.0], [-np.sin(alpha[i]) / l[i], -1.0]])
        out[i] = finv @ (u[i] - dmat @ cmd_l[i])
    return out


def _case(sub, n, seed):
    rng = sub.rng(seed)
    pose_l = np.column_stack([rng.uniform(-3, 3, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    pose = pose_l + np.column_stack([rng.uniform(-3, 3, (n, 2)), rng.uniform(-1, 1, n)])
    cmd_l = np.column_stack([rng.uniform(0.2, 1.5, n), rng.uniform(-0.5, 0.5, n)])
    return pose, pose_l, cmd_l


def _call(sub, pose, pose_l, cmd_l, *args):
    out = sub.follower_cmd(pose.copy(), pose_l.copy(), cmd_l.copy(), *args, xp=np)
    return expect_shape("cmd (follower_cmd)", out, (len(pose), 2))


def _params(sub, k, fixed):
    """(l_ref, alpha_ref, d, k_l, k_alpha): ``fixed``, or drawn with a seed."""
    rng = sub.rng(100 + k)
    return sub.pick(fixed, lambda: tuple(round(float(v), 3) for v in (
        rng.uniform(0.8, 2.0), rng.uniform(-0.8, 0.8), rng.uniform(0.08, 0.3),
        rng.uniform(0.5, 2.0), rng.uniform(0.5, 2.0))))


def check_law(sub):
    pose, pose_l, cmd_l = _case(sub, 7, 1)
    args = _params(sub, 1, (1.5, 0.4, 0.2, 1.3, 0.8))
    found = _call(sub, pose, pose_l, cmd_l, *args)
    compare("cmd (follower_cmd)", _truth(pose, pose_l, cmd_l, *args), found, atol=1e-9,
            case=" at random follower and leader poses (eqs. 2-5)")
    return "eqs. 2-5 at 7 random configurations"


def check_library(sub):
    pose, pose_l, cmd_l = _case(sub, 9, 2)
    rng = sub.rng(3)
    l_ref = sub.pick(np.linspace(0.8, 2.0, 9), lambda: rng.uniform(0.8, 2.0, 9))
    a_ref = sub.pick(np.linspace(-1.0, 1.0, 9), lambda: rng.uniform(-1.0, 1.0, 9))
    _, _, d, kl, ka = _params(sub, 2, (None, None, 0.15, 0.9, 1.4))
    found = _call(sub, pose, pose_l, cmd_l, l_ref, a_ref, d, kl, ka)
    want = leader_follower_law(pose, pose_l, cmd_l, l_ref, a_ref, d, kl, ka)
    compare("cmd (follower_cmd)", want, found, atol=1e-9,
            case=" with per-agent references, against controllers.leader_follower_law")
    return "the library's leader_follower_law, per-agent references"


def _step(pose, cmd, h):
    """The exact unicycle motion over h under a constant command."""
    v, w, th = cmd[:, 0], cmd[:, 1], pose[:, 2]
    small = np.abs(w) < 1e-12
    ws = np.where(small, 1.0, w)
    dx = np.where(small, v * h * np.cos(th), v / ws * (np.sin(th + w * h) - np.sin(th)))
    dy = np.where(small, v * h * np.sin(th), -v / ws * (np.cos(th + w * h) - np.cos(th)))
    return pose + np.column_stack([dx, dy, w * h])


def check_kinematics(sub):
    pose, pose_l, cmd_l = _case(sub, 6, 3)
    l_ref, a_ref, d, kl, ka = _params(sub, 3, (1.2, -0.3, 0.1, 0.7, 1.1))
    cmd = _call(sub, pose, pose_l, cmd_l, l_ref, a_ref, d, kl, ka)
    h = 1e-5                            # central differences: error O(h^2)
    l0, a0, _ = _s(pose, pose_l, d)
    lp, ap, _ = _s(_step(pose, cmd, h), _step(pose_l, cmd_l, h), d)
    lm, am, _ = _s(_step(pose, cmd, -h), _step(pose_l, cmd_l, -h), d)
    rates = np.column_stack([(lp - lm) / (2 * h), _wrap(ap - am) / (2 * h)])
    want = np.column_stack([kl * (l_ref - l0), ka * _wrap(a_ref - a0)])
    compare("cmd (as d/dt of (l, alpha), finite differences)", want, rates, atol=1e-6,
            case=" must give dl/dt = K_l (l_ref - l), dalpha/dt = K_alpha (alpha_ref - alpha)")
    return "finite differences of eq. 2: ds/dt = (u_l, u_alpha)"


POSE0 = np.array([[0.0, 0.0, 0.0], [-1.5, 0.8, 0.2], [-2.5, -1.2, -0.3], [-3.0, 0.1, 0.4]])


def _closed_loop(sub, pose0, lead_cmd, k_l, k_alpha, t_final):
    n = 4
    block = sub.MyFormation(n, l_ref=[1.0, 1.0, 2.0], alpha_ref=[0.6, -0.6, 0.0], d=0.1,
                            k_l=k_l, k_alpha=k_alpha)
    dg = Diagram()
    fleet = dg.add(Unicycle(pose0=pose0), name="fleet")
    lead = dg.add(Constant(np.tile(lead_cmd, (n, 1))), name="lead")
    form = dg.add(block, name="form")
    dg.connect(fleet.pose, form.pose)
    dg.connect(lead.y, form.cmd_in)
    dg.connect(form.cmd, fleet.cmd)
    res = simulate(dg, t_final, dt=0.01, log=[fleet.pose])
    return res.t, res[fleet.pose]


def check_closed_loop(sub):
    rng = sub.rng(4)
    k_l, k_a = sub.pick((1.5, 2.0), lambda: (round(float(rng.uniform(1.5, 2.2)), 3),
                                             round(float(rng.uniform(1.6, 2.5)), 3)))

    def perturbed():
        """The followers start a little elsewhere, each with a distance error
        of at least 0.2 m (the decay ratio is measured on it)."""
        for _ in range(100):
            dp = np.column_stack([rng.uniform(-0.2, 0.2, (4, 2)), rng.uniform(-0.1, 0.1, 4)])
            dp[0] = 0.0
            p0 = POSE0 + dp
            l, _, _ = _s(p0[1:], np.repeat(p0[:1], 3, axis=0), 0.1)
            if np.all(np.abs(np.array([1.0, 1.0, 2.0]) - l) > 0.2):
                return p0
        return POSE0

    pose0 = sub.pick(POSE0, perturbed)
    v0, w0 = sub.pick((0.8, 0.15), lambda: (round(float(rng.uniform(0.5, 1.0)), 3),
                                            round(float(rng.uniform(-0.2, 0.2)), 3)))
    t, traj = _closed_loop(sub, pose0, [v0, w0], k_l, k_a, 12.0)
    l_ref = np.array([1.0, 1.0, 2.0])
    a_ref = np.array([0.6, -0.6, 0.0])
    errs = []
    for k in (0, np.searchsorted(t, 2.0), len(t) - 1):
        l, a, _ = _s(traj[k, 1:], np.repeat(traj[k, :1], 3, axis=0), 0.1)
        errs.append((l_ref - l, _wrap(a_ref - a)))
    e_end = np.abs(np.column_stack(errs[-1])).max()
    if not e_end < 1e-6:
        i = int(np.argmax(np.abs(np.column_stack(errs[-1])).max(axis=1)))
        raise Failed(f"follower {i + 1} behind a turning leader (v_0 = {v0:g}, omega_0 = "
                     f"{w0:g}): "
                     f"formation error (l, alpha) {np.column_stack(errs[-1])[i].round(4)} "
                     f"after 12 s; expected below 1e-6")
    ratio = errs[1][0] / errs[0][0]
    compare("l (distance error ratio e(2 s) / e(0))", np.full(3, np.exp(-2 * k_l)), ratio,
            atol=1e-5, case=f" must be exp(-K_l t) with K_l = {k_l}")
    return f"formation error {e_end:.1e} after 12 s; e_l decays as exp(-K_l t)"


LAB = Lab(3, "formation", "Leader-following formations: the paper's eqs. 2-5 and the "
          "gains", names=("follower_cmd", "MyFormation"),
          checks=[("the law (eqs. 2-5)", check_law),
                  ("same as controllers.leader_follower_law", check_library),
                  ("ds/dt = (u_l, u_alpha) by finite differences", check_kinematics),
                  ("closed loop behind a turning leader", check_closed_loop)])
