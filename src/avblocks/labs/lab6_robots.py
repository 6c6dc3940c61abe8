"""Lab 6's checks: the same controller in simulation and on (emulated) robots.

Independent truth: the go-to-goal law of the library while every robot is
fresh, exact zeros while any is silent, and the law again once every robot
reports again (a hold that latches fails, whether it latches in an
attribute or in a state); the closed loop with ``vehicles.Unicycle``
against ``controllers.PointToPoint``, and against the same law gated here
by a silence between 3 and 4.5 s; then, as ``tests/interfaces``' robot
tests do, the robot emulator (``avblocks robots emulate``, a subprocess)
over a Zenoh router on loopback: the unchanged diagram with
``interfaces.ros2.Robots`` in place of the model, one robot falling silent
mid-run. What the robots received (the emulator's log) must show the
whole group held still after the silence, and the run's real-time report
(overruns, worst lateness) is part of the result. The emulator runs in a
session of its own and is killed with everything it started on every way
out of the check.

With a seed (``--seed``, ``--student``) the poses, goals and gains of the
first checks are drawn per student.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ..blocks import Constant
from ..controllers import PointToPoint, point_to_point_law
from ..core.block import Block
from ..core.diagram import Diagram
from ..core.frontend import simulate
from ..vehicles import Unicycle
from . import oscalls
from .grading import Failed, Lab, check_ports, compare, expect_shape, fmt

GOAL = np.array([[3.0, 0.0], [3.0, 2.0]])


def _cmd(block, pose, fresh):
    y = block.output(0.0, block.initial_state(), {"pose": pose.copy(), "fresh": fresh.copy()},
                     np)
    if not isinstance(y, dict) or "cmd" not in y:
        raise Failed(f"output must return {{'cmd': (N, 2) array}}, returned "
                     f"{type(y).__name__}" + (f" with keys {list(y)}" if isinstance(y, dict)
                                              else ""))
    return expect_shape("cmd", y["cmd"], (len(pose), 2))


def check_ports_(sub):
    return check_ports(sub.GroupHold(np.zeros((3, 2))), inputs={"pose": (3, 3), "fresh": (3,)},
                       outputs={"cmd": (3, 2)})


def check_law(sub):
    rng = sub.rng(1)
    n = 5
    goal = rng.uniform(-3, 3, (n, 2))
    pose = np.column_stack([rng.uniform(-3, 3, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    d, k, vmax = sub.pick((0.2, 0.8, 0.3), lambda: tuple(round(float(v), 3) for v in (
        rng.uniform(0.1, 0.3), rng.uniform(0.5, 1.5), rng.uniform(0.2, 0.5))))
    b = sub.GroupHold(goal, d=d, gain=k, v_max=vmax)
    law = point_to_point_law(pose, goal, d, k, vmax)
    compare("cmd", law, _cmd(b, pose, np.ones(n, bool)), atol=1e-12,
            case=" with every robot fresh: the go-to-goal law")
    for silent in (0, 3):
        fresh = np.ones(n, bool)
        fresh[silent] = False
        compare("cmd", np.zeros((n, 2)), _cmd(b, pose, fresh), atol=0.0,
                case=f" with robot {silent} silent (fresh false): every robot held")
    # the same block, once every robot reports again: the hold must end by itself
    compare("cmd", law, _cmd(b, pose, np.ones(n, bool)), atol=1e-12,
            case=" with every robot fresh again after robots 0 and 3 were silent: the "
                 "go-to-goal law (a hold must end by itself when all report again)")
    return "the law while all are fresh; all zero when any is silent; the law again after"


class _Silence(Block):
    """``fresh`` (N,) bool: every robot fresh except robot ``who`` in
    [t0, t1)."""

    def __init__(self, n, who, t0, t1):
        super().__init__()
        self.n, self.who, self.t0, self.t1 = n, who, t0, t1
        self.declare_output("fresh", (n,), dtype="bool")

    def output(self, t, x, u, xp):
        silent = (xp.arange(self.n) == self.who) & (t >= self.t0) & (t < self.t1)
        return {"fresh": ~silent}


class _Gate(Block):
    """``cmd = law`` while every robot is fresh, zeros otherwise: the group
    hold written here, independently of the student's."""

    def __init__(self, n):
        super().__init__()
        self.declare_input("law", (n, 2))
        self.declare_input("fresh", (n,), dtype="bool")
        self.declare_output("cmd", (n, 2))

    def output(self, t, x, u, xp):
        return {"cmd": u["law"] * xp.all(u["fresh"])}


def check_resumes(sub):
    """In simulation: held while robot 1 is silent (3 to 4.5 s), then going
    on, against the library's law gated here."""
    pose0 = np.array([[0.0, 0.0, 0.0], [0.0, 2.0, 0.0]])
    t0, t1 = 3.0, 4.5
    runs = []
    for mine in (True, False):
        d = Diagram()
        fleet = d.add(Unicycle(pose0=pose0), name="fleet")
        silence = d.add(_Silence(2, 1, t0, t1), name="silence")
        if mine:
            drive = d.add(sub.GroupHold(GOAL, d=0.2, gain=1.0, v_max=0.2), name="drive")
            d.connect(fleet.pose, drive.pose)
            d.connect(silence.fresh, drive.fresh)
            d.connect(drive.cmd, fleet.cmd)
        else:
            law = d.add(PointToPoint(GOAL[:, None, :], d=0.2, gain=1.0, v_max=0.2,
                                     radius=1e-9), name="law")
            gate = d.add(_Gate(2), name="gate")
            d.connect(fleet.pose, law.pose)
            d.connect(law.cmd, gate.law)
            d.connect(silence.fresh, gate.fresh)
            d.connect(gate.cmd, fleet.cmd)
        res = simulate(d, 10.0, dt=0.05, log=[fleet.pose])
        runs.append((res.t, np.asarray(res[fleet.pose])))
    (t, mine), (_, ref) = runs
    during = (t > t0 + 0.05) & (t < t1 - 0.05)
    moved = np.abs(np.diff(mine[during], axis=0)).max() if during.sum() > 1 else 0.0
    if moved > 1e-12:
        raise Failed(f"the robots moved (by up to {moved:.3g} m a step) while robot 1 was "
                     f"silent between {t0:g} and {t1:g} s; expected the whole group held")
    after = t > t1 + 0.5
    if np.abs(mine[after][-1] - mine[after][0]).max() < 1e-6:
        raise Failed(f"the robots did not move again after robot 1 reported again at "
                     f"{t1:g} s (still at {fmt(mine[-1, :, :2].ravel())} at 10 s): the hold "
                     f"latched; it must end by itself when every robot is fresh again")
    compare("pose (of the simulated vehicles)", ref[-1], mine[-1], atol=1e-9,
            case=f" after 10 s, robot 1 silent from {t0:g} to {t1:g} s, against the "
                 f"library's law held while a robot is silent")
    return f"held from {t0:g} to {t1:g} s, then went on as the library's law does"


def check_simulation(sub):
    pose0 = np.array([[0.0, 0.0, 0.0], [0.0, 2.0, 0.0]])
    runs = []
    for block in (sub.GroupHold(GOAL, d=0.2, gain=1.0, v_max=0.2),
                  PointToPoint(GOAL[:, None, :], d=0.2, gain=1.0, v_max=0.2, radius=1e-9)):
        d = Diagram()
        fleet = d.add(Unicycle(pose0=pose0), name="fleet")
        drive = d.add(block, name="drive")
        d.connect(fleet.pose, drive.pose)
        if "fresh" in block.input_ports:
            ok = d.add(Constant(np.ones(2, bool)), name="ok")
            d.connect(ok.y, drive.fresh)
        d.connect(drive.cmd, fleet.cmd)
        runs.append(simulate(d, 10.0, dt=0.05, log=[fleet.pose])[fleet.pose])
    compare("pose (of the simulated vehicles)", runs[1][-1], runs[0][-1], atol=1e-9,
            case=" after 10 s with vehicles.Unicycle, against controllers.PointToPoint")
    return "in simulation, the same run as controllers.PointToPoint"


def _emulator(endpoint, log, tmp):
    """The robot emulator under the sandbox's supervisor: it and all it
    starts die when the check stops it, and also when the grader itself is
    killed (:class:`avblocks.labs.oscalls.Supervised`). Its environment is
    the sandbox's, not the grader's."""
    import avblocks
    src = str(Path(avblocks.__file__).resolve().parents[1])
    # not the grader's environment: a student's process of the same user can
    # read the emulator's /proc/<pid>/environ (the instructor's tokens and keys)
    env = {**oscalls.child_environment(tmp),
           "PYTHONPATH": os.pathsep.join(x for x in (src, os.environ.get("PYTHONPATH")) if x)}
    cmd = [sys.executable, "-m", "avblocks", "robots", "emulate", "--names", "tb1,tb2",
           "--router", endpoint, "--log", str(log), "--rate", "50",
           "--pose0", "[[0, 0, 0], [0, 2, 0]]", "--drop", "tb2@2.0"]
    return oscalls.Supervised(cmd, env=env, cwd=tmp, stdout=subprocess.PIPE,
                              stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, text=True)


def _stop_emulator(emu):
    """Stop the emulator politely first (it writes its log), then kill it
    with everything it started."""
    emu.terminate(10.0)
    emu.kill()
    if emu.proc.stdout is not None:
        emu.proc.stdout.close()


def check_on_robots(sub):
    try:
        import zenoh  # noqa: F401

        from ..interfaces.ros2 import Robots, open_router
    except ImportError as e:
        raise Failed(f"this check drives the robot emulator over Zenoh and needs the ros2 "
                     f"extra: pip install 'avblocks[ros2]' ({e})") from None
    session, endpoint = open_router()
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "emulator.jsonl"
        emu = _emulator(endpoint, log, tmp)
        try:
            t_end = time.monotonic() + 20
            while not (log.exists() and log.stat().st_size) and time.monotonic() < t_end:
                if emu.exit_code(0.0) is not None or emu.proc.poll() is not None:
                    raise Failed("the robot emulator exited before it logged anything")
                time.sleep(0.05)
            time.sleep(0.3)
            d = Diagram()
            fleet = d.add(Robots(["tb1", "tb2"], router=endpoint, timeout=0.3), name="fleet")
            drive = d.add(sub.GroupHold(GOAL, d=0.2, gain=1.0, v_max=0.2), name="drive")
            d.connect(fleet.pose, drive.pose)
            d.connect(fleet.fresh, drive.fresh)
            d.connect(drive.cmd, fleet.cmd)
            res = simulate(d, 4.0, dt=0.05, realtime=1.0,
                           log=["fleet.pose", "fleet.fresh", "drive.cmd"])
            time.sleep(0.5)                     # the last commands reach the emulator
        finally:
            _stop_emulator(emu)
            session.close()
        recs = [json.loads(s) for s in log.read_text().splitlines() if s.strip()]
    drop = [r for r in recs if r["ev"] == "drop"]
    if not drop:
        raise Failed("the emulator never dropped tb2 (the run was shorter than 2 s?)")
    t_drop = drop[0]["wall"]
    tb1 = [r for r in recs if r["ev"] == "cmd" and r["robot"] == "tb1"]
    before = [c for c in tb1 if c["wall"] < t_drop]
    if not any(c["v"] != 0 for c in before):
        raise Failed("robot tb1 received no motion command while both robots reported "
                     "(the controller held a fresh group?)")
    late = [c for c in tb1 if c["wall"] > t_drop + 0.3 + 0.4]
    moving = [c for c in late if c["v"] != 0 or c["w"] != 0]
    if not late or moving:
        raise Failed(f"after tb2 fell silent (watchdog 0.3 s), tb1 still received "
                     f"{len(moving)} motion commands, e.g. v = {moving[0]['v']:.3f}, "
                     f"w = {moving[0]['w']:.3f}; expected the whole group held at zero"
                     if moving else "no command reached tb1 after tb2 fell silent")
    fresh = np.asarray(res["fleet.fresh"])
    cmd = np.asarray(res["drive.cmd"])
    stale = ~fresh.all(axis=1)
    if np.any(cmd[stale] != 0):
        raise Failed("the controller's cmd was not zero while a robot was silent")
    steps = int(res.meta.get("steps", len(res.t)))
    over = int(res.meta.get("overruns", 0))
    return (f"on the emulator: tb1 drove, then held when tb2 fell silent; paced {over} of "
            f"{steps} steps overran, worst lateness {1e3 * res.meta.get('max_lateness', 0):.1f} "
            f"ms")


LAB = Lab(6, "robots", "From simulation to robots: the ROS 2 emulator over Zenoh, the "
          "watchdog, the real-time report", names=("GroupHold",),
          checks=[("ports", check_ports_), ("the law and the group hold", check_law),
                  ("in simulation: same as controllers.PointToPoint", check_simulation),
                  ("in simulation: held while a robot is silent, then goes on",
                   check_resumes),
                  ("on the robot emulator over Zenoh", check_on_robots)])
