"""Lab 1's checks: the unicycle and the differential drive.

Independent truth: the closed form of eq. 1 at random poses, with turn
rates beyond pi (a rate is not an angle: wrapping it is a mistake the
check names); the exact solution of a constant command (an arc of radius
v / omega, or a straight line), against which an RK4 run of the student's
block must be within 1e-6 m; the library's ``vehicles.Unicycle`` under a
changing command; and the wheel map's closed form.

With a seed (``--seed``, ``--student``) the poses, commands, the changing
command's amplitude and the wheel geometry are drawn per student.
"""

from __future__ import annotations

import numpy as np

from ..blocks import Constant
from ..core.block import Block
from ..core.diagram import Diagram
from ..core.frontend import simulate
from ..vehicles import Unicycle
from .grading import Failed, Lab, check_ports, compare, expect_shape, fmt


class _Wavy(Block):
    """A changing command for N agents: v = 1 + a sin(t + i),
    omega = b cos(0.7 t + i)."""

    def __init__(self, n, a=0.5, b=0.8):
        super().__init__()
        self.n, self.a, self.b = n, float(a), float(b)
        self.declare_output("cmd", (n, 2))

    def output(self, t, x, u, xp):
        i = xp.arange(self.n)
        return {"cmd": xp.stack([1.0 + self.a * xp.sin(t + i),
                                 self.b * xp.cos(0.7 * t + i)], axis=-1)}


def _block(sub, n=4, seed=0):
    rng = sub.rng(seed)
    pose0 = np.column_stack([rng.uniform(-5, 5, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    return sub.MyUnicycle(pose0), pose0


def _wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def check_ports_(sub):
    b, _ = _block(sub)
    return check_ports(b, inputs={"cmd": (4, 2)}, outputs={"pose": (4, 3)},
                       states={"pose": (4, 3)})


def check_derivative(sub):
    b, _ = _block(sub, n=6)
    rng = sub.rng(1)
    pose = np.column_stack([rng.uniform(-5, 5, (6, 2)), rng.uniform(-np.pi, np.pi, 6)])
    cmd = np.column_stack([rng.uniform(-2, 2, 6), rng.uniform(-1, 1, 6)])
    # turn rates beyond pi rad/s: omega is a rate, never wrapped like an angle
    cmd[4:, 1] = sub.pick([4.0, -5.5], lambda: rng.uniform(3.5, 6.0, 2) * [1, -1])
    dx = b.derivative(0.0, {"pose": pose.copy()}, {"cmd": cmd.copy()}, np)
    if not isinstance(dx, dict) or "pose" not in dx:
        keys = f" with keys {list(dx)}" if isinstance(dx, dict) else ""
        raise Failed(f"derivative must return {{'pose': (N, 3) rates}}, returned "
                     f"{type(dx).__name__}{keys}")
    want = np.column_stack([cmd[:, 0] * np.cos(pose[:, 2]), cmd[:, 0] * np.sin(pose[:, 2]),
                            cmd[:, 1]])
    found = expect_shape("pose (its rate, derivative)", dx["pose"], want.shape)
    wrapped = np.column_stack([want[:, :2], _wrap(want[:, 2])])
    if not np.allclose(found, want, atol=1e-12) and np.allclose(found, wrapped, atol=1e-12):
        i = int(np.argmax(np.abs(found[:, 2] - want[:, 2])))
        raise Failed(f"port `pose (its rate, derivative)`, agent {i}: dtheta/dt = "
                     f"{found[i, 2]:.4f} for a turn rate omega = {cmd[i, 1]:.4f} rad/s: the "
                     f"rate was wrapped into (-pi, pi] like an angle; dtheta/dt = omega as it "
                     f"is (wrap_angle is for headings, not for rates)")
    compare("pose (its rate, derivative)", want, found, atol=1e-12,
            case=" at random poses and commands (two turn rates beyond pi rad/s)")
    return "eq. 1 at 6 random poses and commands, turn rates up to 5.5 rad/s"


def _exact(pose0, v, w, t):
    """The exact pose after a constant (v, omega) for time t."""
    x, y, th = pose0.T
    th1 = th + w * t
    small = np.abs(w) < 1e-12
    ws = np.where(small, 1.0, w)
    x1 = np.where(small, x + v * t * np.cos(th), x + v / ws * (np.sin(th1) - np.sin(th)))
    y1 = np.where(small, y + v * t * np.sin(th), y - v / ws * (np.cos(th1) - np.cos(th)))
    return np.column_stack([x1, y1, th1])


def _run(block, cmd, t_final, dt, solver):
    d = Diagram()
    fleet = d.add(block, name="fleet")
    src = d.add(Constant(cmd), name="cmd")
    d.connect(src.y, fleet.cmd)
    res = simulate(d, t_final, dt=dt, solver=solver, log=[fleet.pose])
    return res[fleet.pose]


def check_exact_solution(sub):
    b, pose0 = _block(sub, n=4, seed=2)
    rng = sub.rng(5)
    cmd = sub.pick(np.array([[1.0, 0.5], [2.0, -0.3], [0.7, 0.0], [-1.0, 1.0]]),
                   lambda: np.column_stack([rng.uniform(-2, 2, 4),
                                            rng.uniform(-1.2, 1.2, 4) * [1, 1, 0, 1]]))
    final = _run(b, cmd, 10.0, 0.05, "rk4")[-1]
    err = compare("pose", _exact(pose0, cmd[:, 0], cmd[:, 1], 10.0), final, atol=1e-6,
                  case=" after 10 s of a constant command (RK4, dt = 0.05 s; arcs and a "
                       "straight line, exact solution)")
    return f"largest error {err:.1e} m against the exact arcs"


def check_against_library(sub):
    b, pose0 = _block(sub, n=5, seed=3)
    rng = sub.rng(6)
    a, w = sub.pick((0.5, 0.8), lambda: (rng.uniform(0.2, 0.8), rng.uniform(0.4, 1.2)))
    mine = Diagram()
    f1 = mine.add(b, name="fleet")
    s1 = mine.add(_Wavy(5, a, w), name="cmd")
    mine.connect(s1.cmd, f1.cmd)
    r1 = simulate(mine, 8.0, dt=0.02, log=[f1.pose])[f1.pose]
    ref = Diagram()
    f2 = ref.add(Unicycle(pose0=pose0), name="fleet")
    s2 = ref.add(_Wavy(5, a, w), name="cmd")
    ref.connect(s2.cmd, f2.cmd)
    r2 = simulate(ref, 8.0, dt=0.02, log=[f2.pose])[f2.pose]
    # headings agree modulo 2 pi: vehicles.Unicycle keeps them in (-pi, pi], a
    # student's unicycle may let them run on (both are right)
    mine = np.array(r1[-1], dtype=float)
    mine[:, 2] = r2[-1][:, 2] + _wrap(mine[:, 2] - r2[-1][:, 2])
    compare("pose", r2[-1], mine, atol=1e-9,
            case=" after 8 s of a changing command, against vehicles.Unicycle (headings "
                 "modulo 2 pi)")
    return "the same trajectories as vehicles.Unicycle to 1e-9 m"


def check_wheels(sub):
    rng = sub.rng(4)
    wheels = rng.uniform(-10, 10, (7, 2))
    r, L = sub.pick((0.033, 0.16), lambda: (round(float(rng.uniform(0.02, 0.1)), 4),
                                            round(float(rng.uniform(0.1, 0.5)), 3)))
    found = sub.wheels_to_cmd(wheels.copy(), r, L)
    want = np.column_stack([r * (wheels[:, 1] + wheels[:, 0]) / 2,
                            r * (wheels[:, 1] - wheels[:, 0]) / L])
    compare("cmd (wheels_to_cmd)", want, found, atol=1e-12,
            case=f" for radius {r} m, track {L} m, wheels {fmt(wheels[0], 2)}, ...")
    return "v = r (wR + wL) / 2, omega = r (wR - wL) / L"


LAB = Lab(1, "kinematics", "Vehicle kinematics: the unicycle, the differential drive, "
          "integration error", names=("MyUnicycle", "wheels_to_cmd"),
          checks=[("ports", check_ports_), ("derivative (eq. 1)", check_derivative),
                  ("exact solution of a constant command", check_exact_solution),
                  ("same as vehicles.Unicycle", check_against_library),
                  ("differential drive: wheels_to_cmd", check_wheels)])
