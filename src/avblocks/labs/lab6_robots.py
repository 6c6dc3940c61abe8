"""Lab 6's checks: the same controller in simulation and on (emulated) robots.

Independent truth: the go-to-goal law of the library while every robot is
fresh and exact zeros otherwise; the closed loop with ``vehicles.Unicycle``
against ``controllers.PointToPoint``; then, as ``tests/interfaces``' robot
tests do, the robot emulator (``avblocks robots emulate``, a subprocess)
over a Zenoh router on loopback: the unchanged diagram with
``interfaces.ros2.Robots`` in place of the model, one robot falling silent
mid-run. What the robots received (the emulator's log) must show the
whole group held still after the silence, and the run's real-time report
(overruns, worst lateness) is part of the result.
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
from ..core.diagram import Diagram
from ..core.frontend import simulate
from ..vehicles import Unicycle
from .grading import Failed, Lab, check_ports, compare, expect_shape

GOAL = np.array([[3.0, 0.0], [3.0, 2.0]])


def _cmd(block, pose, fresh):
    y = block.output(0.0, {}, {"pose": pose.copy(), "fresh": fresh.copy()}, np)
    if not isinstance(y, dict) or "cmd" not in y:
        raise Failed(f"output must return {{'cmd': (N, 2) array}}, returned "
                     f"{type(y).__name__}" + (f" with keys {list(y)}" if isinstance(y, dict)
                                              else ""))
    return expect_shape("cmd", y["cmd"], (len(pose), 2))


def check_ports_(mod):
    return check_ports(mod.GroupHold(np.zeros((3, 2))), inputs={"pose": (3, 3), "fresh": (3,)},
                       outputs={"cmd": (3, 2)})


def check_law(mod):
    rng = np.random.default_rng(1)
    n = 5
    goal = rng.uniform(-3, 3, (n, 2))
    pose = np.column_stack([rng.uniform(-3, 3, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    b = mod.GroupHold(goal, d=0.2, gain=0.8, v_max=0.3)
    law = point_to_point_law(pose, goal, 0.2, 0.8, 0.3)
    compare("cmd", law, _cmd(b, pose, np.ones(n, bool)), atol=1e-12,
            case=" with every robot fresh: the go-to-goal law")
    for silent in (0, 3):
        fresh = np.ones(n, bool)
        fresh[silent] = False
        compare("cmd", np.zeros((n, 2)), _cmd(b, pose, fresh), atol=0.0,
                case=f" with robot {silent} silent (fresh false): every robot held")
    return "the law while all are fresh; all zero when any is silent"


def check_simulation(mod):
    pose0 = np.array([[0.0, 0.0, 0.0], [0.0, 2.0, 0.0]])
    runs = []
    for block in (mod.GroupHold(GOAL, d=0.2, gain=1.0, v_max=0.2),
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
    import avblocks
    src = str(Path(avblocks.__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": src + os.pathsep + os.environ.get("PYTHONPATH", "")}
    cmd = [sys.executable, "-m", "avblocks", "robots", "emulate", "--names", "tb1,tb2",
           "--router", endpoint, "--log", str(log), "--rate", "50",
           "--pose0", "[[0, 0, 0], [0, 2, 0]]", "--drop", "tb2@2.0"]
    return subprocess.Popen(cmd, env=env, cwd=tmp, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)


def check_on_robots(mod):
    try:
        import zenoh  # noqa: F401

        from ..interfaces.ros2 import Robots, open_router
    except ImportError as e:
        raise Failed(f"this check drives the robot emulator over Zenoh and needs the ros2 "
                     f"extra: pip install 'avblocks[ros2]' ({e})") from None
    session, endpoint = open_router()
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "emulator.jsonl"
        proc = _emulator(endpoint, log, tmp)
        try:
            t_end = time.monotonic() + 20
            while not (log.exists() and log.stat().st_size) and time.monotonic() < t_end:
                if proc.poll() is not None:
                    raise Failed(f"the robot emulator exited: {proc.stdout.read()[-500:]}")
                time.sleep(0.05)
            time.sleep(0.3)
            d = Diagram()
            fleet = d.add(Robots(["tb1", "tb2"], router=endpoint, timeout=0.3), name="fleet")
            drive = d.add(mod.GroupHold(GOAL, d=0.2, gain=1.0, v_max=0.2), name="drive")
            d.connect(fleet.pose, drive.pose)
            d.connect(fleet.fresh, drive.fresh)
            d.connect(drive.cmd, fleet.cmd)
            res = simulate(d, 4.0, dt=0.05, realtime=1.0,
                           log=["fleet.pose", "fleet.fresh", "drive.cmd"])
            time.sleep(0.5)                     # the last commands reach the emulator
        finally:
            proc.terminate()
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                proc.kill()
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
                  ("on the robot emulator over Zenoh", check_on_robots)])
