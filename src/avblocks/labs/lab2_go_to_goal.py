"""Lab 2's checks: go to a goal by feedback linearisation of the look-ahead point.

Independent truth: the closed form of the inverse map at random poses; the
kinematics of the look-ahead point (its velocity under the student's
command must be ``K (goal - p)``, or have length ``v_max`` when saturated);
the library's ``controllers.PointToPoint`` in closed loop; convergence of
every look-ahead point to its goal.

With a seed (``--seed``, ``--student``) the poses, goals, look-ahead
distance, gain and speed limit are drawn per student.
"""

from __future__ import annotations

import numpy as np

from ..controllers import PointToPoint
from ..core.diagram import Diagram
from ..core.frontend import simulate
from ..vehicles import Unicycle
from .grading import Failed, Lab, check_ports, compare, expect_shape, fmt


def _poses(sub, n, seed, spread=5.0):
    rng = sub.rng(seed)
    return np.column_stack([rng.uniform(-spread, spread, (n, 2)),
                            rng.uniform(-np.pi, np.pi, n)])


def _cmd(block, pose):
    y = block.output(0.0, {}, {"pose": pose.copy()}, np)
    if not isinstance(y, dict) or "cmd" not in y:
        raise Failed(f"output must return {{'cmd': (N, 2) array}}, returned "
                     f"{type(y).__name__}" + (f" with keys {list(y)}" if isinstance(y, dict)
                                              else ""))
    return expect_shape("cmd", y["cmd"], (len(pose), 2))


def _point_velocity(pose, cmd, d):
    c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
    v, w = cmd[:, 0], cmd[:, 1]
    return np.column_stack([v * c - d * w * s, v * s + d * w * c])


def check_ports_(sub):
    b = sub.GoToGoal(np.zeros((4, 2)))
    return check_ports(b, inputs={"pose": (4, 3)}, outputs={"cmd": (4, 2)})


def _gains(sub, k, fixed):
    rng = sub.rng(100 + k)
    return sub.pick(fixed, lambda: (round(float(rng.uniform(0.1, 0.3)), 3),
                                    round(float(rng.uniform(0.6, 2.0)), 3)))


def check_law(sub):
    n = 6
    d, k = _gains(sub, 1, (0.2, 0.8))
    pose = _poses(sub, n, 1, spread=1.0)
    goal = sub.rng(2).uniform(-1, 1, (n, 2))
    b = sub.GoToGoal(goal, d=d, gain=k, v_max=100.0)        # never saturated here
    cmd = _cmd(b, pose)
    c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
    w = k * (goal - pose[:, :2] - d * np.column_stack([c, s]))
    want = np.column_stack([c * w[:, 0] + s * w[:, 1], (-s * w[:, 0] + c * w[:, 1]) / d])
    compare("cmd", want, cmd, atol=1e-9, case=f" (d = {d}, K = {k}, unsaturated)")
    # the point the law linearises moves as K (goal - p)
    compare("cmd (as the look-ahead point's velocity)", w, _point_velocity(pose, cmd, d),
            atol=1e-9, case=" must give dp/dt = K (goal - p)")
    return "v, omega from the inverse map; dp/dt = K (goal - p)"


def check_saturation(sub):
    n, vmax = 5, sub.pick(0.5, lambda: round(float(sub.rng(7).uniform(0.3, 1.5)), 3))
    d, k = _gains(sub, 2, (0.1, 2.0))
    pose = _poses(sub, n, 3)
    goal = pose[:, :2] + 40.0 * sub.rng(4).normal(size=(n, 2))   # far away
    cmd = _cmd(sub.GoToGoal(goal, d=d, gain=k, v_max=vmax), pose)
    pdot = _point_velocity(pose, cmd, d)
    p = pose[:, :2] + d * np.column_stack([np.cos(pose[:, 2]), np.sin(pose[:, 2])])
    e = goal - p
    want = vmax * e / np.linalg.norm(e, axis=1, keepdims=True)
    compare("cmd (as the look-ahead point's velocity)", want, pdot, atol=1e-9,
            case=f" for far goals: length v_max = {vmax} towards the goal")
    return f"far goals: the point moves at v_max = {vmax} straight at its goal"


def _closed_loop(block, pose0, t_final, dt=0.01):
    dg = Diagram()
    fleet = dg.add(Unicycle(pose0=pose0), name="fleet")
    drive = dg.add(block, name="drive")
    dg.connect(fleet.pose, drive.pose)
    dg.connect(drive.cmd, fleet.cmd)
    return simulate(dg, t_final, dt=dt, log=[fleet.pose])[fleet.pose]


def check_against_library(sub):
    n, vmax = 8, 1.0
    d, k = _gains(sub, 3, (0.15, 1.2))
    pose0 = _poses(sub, n, 5)
    goal = sub.rng(6).uniform(-6, 6, (n, 2))
    mine = _closed_loop(sub.GoToGoal(goal, d=d, gain=k, v_max=vmax), pose0, 6.0)
    ref = _closed_loop(PointToPoint(goal[:, None, :], d=d, gain=k, v_max=vmax, radius=1e-9),
                       pose0, 6.0)
    compare("pose (of the vehicles driven)", ref[-1], mine[-1], atol=1e-8,
            case=" after 6 s in closed loop, against controllers.PointToPoint")
    return "the same closed loop as controllers.PointToPoint to 1e-8 m"


def check_converges(sub):
    n, vmax = 10, 1.0
    d, k = sub.pick((0.1, 1.0), lambda: (round(float(sub.rng(9).uniform(0.1, 0.3)), 3),
                                         round(float(sub.rng(10).uniform(0.8, 2.0)), 3)))
    pose0 = _poses(sub, n, 7)
    goal = sub.rng(8).uniform(-5, 5, (n, 2))
    final = _closed_loop(sub.GoToGoal(goal, d=d, gain=k, v_max=vmax), pose0, 30.0, dt=0.02)[-1]
    p = final[:, :2] + d * np.column_stack([np.cos(final[:, 2]), np.sin(final[:, 2])])
    miss = np.linalg.norm(p - goal, axis=1)
    if np.all(miss < 1e-3):
        return f"all {n} look-ahead points within {miss.max():.1e} m of their goals at 30 s"
    i = int(np.argmax(miss))
    raise Failed(f"agent {i}'s look-ahead point is {miss[i]:.3g} m from its goal "
                 f"{fmt(goal[i])} after 30 s (started at pose {fmt(pose0[i])}); "
                 f"expected < 1e-3 m")


LAB = Lab(2, "go_to_goal", "Go to goal and waypoints: feedback linearisation of the "
          "look-ahead point", names=("GoToGoal",),
          checks=[("ports", check_ports_), ("the law (inverse map)", check_law),
                  ("saturation at v_max", check_saturation),
                  ("same as controllers.PointToPoint", check_against_library),
                  ("closed loop reaches the goals", check_converges)])
