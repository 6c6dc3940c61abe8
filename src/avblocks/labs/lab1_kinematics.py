"""Lab 1's checks: the unicycle and the differential drive.

Independent truth: the closed form of eq. 1 at random poses; the exact
solution of a constant command (an arc of radius v / omega, or a straight
line), against which an RK4 run of the student's block must be within
1e-6 m; the library's ``vehicles.Unicycle`` under a changing command; and
the wheel map's closed form.
"""

from __future__ import annotations

import numpy as np

from ..blocks import Constant
from ..core.block import Block
from ..core.diagram import Diagram
from ..core.frontend import simulate
from ..vehicles import Unicycle
from .grading import Failed, Lab, check_ports, compare, fmt


class _Wavy(Block):
    """A changing command for N agents: v = 1 + 0.5 sin(t + i),
    omega = 0.8 cos(0.7 t + i)."""

    def __init__(self, n):
        super().__init__()
        self.n = n
        self.declare_output("cmd", (n, 2))

    def output(self, t, x, u, xp):
        i = xp.arange(self.n)
        return {"cmd": xp.stack([1.0 + 0.5 * xp.sin(t + i), 0.8 * xp.cos(0.7 * t + i)],
                                axis=-1)}


def _block(mod, n=4, seed=0):
    rng = np.random.default_rng(seed)
    pose0 = np.column_stack([rng.uniform(-5, 5, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    return mod.MyUnicycle(pose0), pose0


def check_ports_(mod):
    b, _ = _block(mod)
    return check_ports(b, inputs={"cmd": (4, 2)}, outputs={"pose": (4, 3)},
                       states={"pose": (4, 3)})


def check_derivative(mod):
    b, _ = _block(mod, n=6)
    rng = np.random.default_rng(1)
    pose = np.column_stack([rng.uniform(-5, 5, (6, 2)), rng.uniform(-np.pi, np.pi, 6)])
    cmd = np.column_stack([rng.uniform(-2, 2, 6), rng.uniform(-1, 1, 6)])
    dx = b.derivative(0.0, {"pose": pose.copy()}, {"cmd": cmd.copy()}, np)
    if not isinstance(dx, dict) or "pose" not in dx:
        keys = f" with keys {list(dx)}" if isinstance(dx, dict) else ""
        raise Failed(f"derivative must return {{'pose': (N, 3) rates}}, returned "
                     f"{type(dx).__name__}{keys}")
    want = np.column_stack([cmd[:, 0] * np.cos(pose[:, 2]), cmd[:, 0] * np.sin(pose[:, 2]),
                            cmd[:, 1]])
    compare("pose (its rate, derivative)", want, dx["pose"], atol=1e-12,
            case=" at random poses and commands")
    return "eq. 1 at 6 random poses and commands"


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


def check_exact_solution(mod):
    b, pose0 = _block(mod, n=4, seed=2)
    cmd = np.array([[1.0, 0.5], [2.0, -0.3], [0.7, 0.0], [-1.0, 1.0]])
    final = _run(b, cmd, 10.0, 0.05, "rk4")[-1]
    err = compare("pose", _exact(pose0, cmd[:, 0], cmd[:, 1], 10.0), final, atol=1e-6,
                  case=" after 10 s of a constant command (RK4, dt = 0.05 s; arcs and a "
                       "straight line, exact solution)")
    return f"largest error {err:.1e} m against the exact arcs"


def check_against_library(mod):
    b, pose0 = _block(mod, n=5, seed=3)
    mine = Diagram()
    f1 = mine.add(b, name="fleet")
    s1 = mine.add(_Wavy(5), name="cmd")
    mine.connect(s1.cmd, f1.cmd)
    r1 = simulate(mine, 8.0, dt=0.02, log=[f1.pose])[f1.pose]
    ref = Diagram()
    f2 = ref.add(Unicycle(pose0=pose0), name="fleet")
    s2 = ref.add(_Wavy(5), name="cmd")
    ref.connect(s2.cmd, f2.cmd)
    r2 = simulate(ref, 8.0, dt=0.02, log=[f2.pose])[f2.pose]
    compare("pose", r2[-1], r1[-1], atol=1e-9,
            case=" after 8 s of a changing command, against vehicles.Unicycle")
    return "the same trajectories as vehicles.Unicycle to 1e-9 m"


def check_wheels(mod):
    rng = np.random.default_rng(4)
    wheels = rng.uniform(-10, 10, (7, 2))
    r, L = 0.033, 0.16
    found = mod.wheels_to_cmd(wheels.copy(), r, L)
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
