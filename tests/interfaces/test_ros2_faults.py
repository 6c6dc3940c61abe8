"""Faults real deployments meet, against the robot emulator (a subprocess)
over real Zenoh on loopback: malformed pose payloads, the commanding
process killed with SIGKILL, the Zenoh router restarted or gone, and two
processes commanding the same robots."""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

import avblocks as av

from .conftest import _need, commands, emulator, env, read_log, wait_for_stop

HERE = Path(__file__).resolve().parent
KINDS = ("truncated", "wrong_type", "nan", "inf", "huge", "bad_header")


def _robots(router, names, **kw):
    from avblocks.interfaces.ros2 import Robots
    return Robots(names.split(","), router=router, **kw)


def _drive(robots, v=0.2):
    d = av.Diagram()
    c = d.add(av.blocks.Constant(np.tile([v, 0.0], (robots.n, 1))), name="c")
    f = d.add(robots, name="fleet")
    d.connect(c.y, f.cmd)
    return d


def _events(recs, ev, robot=None):
    return [r for r in recs if r["ev"] == ev and (robot is None or r["robot"] == robot)]


def _wait_moving(log, robot, timeout=20.0, after=0.0):
    """Wall time of the first nonzero command ``robot`` received after ``after``."""
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        if Path(log).exists():
            got = [c for c in commands(read_log(log), robot) if c["v"] > 0
                   and c["wall"] > after]
            if got:
                return got[0]["wall"]
        time.sleep(0.02)
    raise AssertionError(f"{robot} never received a command")


def _fleet_process(router, names, t_final=30.0):
    return subprocess.Popen([sys.executable, str(HERE / "_fleet_run.py"), router, names,
                             str(t_final)], env=env(), stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)


def _router_process(endpoint):
    p = subprocess.Popen([sys.executable, "-m", "avblocks", "robots", "router", "--listen",
                          endpoint], env=env(), stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, text=True)
    line = p.stdout.readline()
    assert "listening" in line, line
    return p


# ------------------------------------------------------------------ bad traffic
def test_malformed_pose_payloads_are_counted_ignored_and_the_robot_counts_as_silent(
        router, tmp_path):
    from avblocks.interfaces.ros2 import RobotWarning
    names = ["tb0"] + [f"tb{k + 1}" for k in range(len(KINDS))]
    p0 = [[0.0, float(k), 0.0] for k in range(len(names))]
    extra = ["--pose0", str(p0), "--rate", 50]
    for k, kind in enumerate(KINDS):
        extra += ["--corrupt", f"tb{k + 1}@0.5:{kind}"]
    with emulator(router, ",".join(names), tmp_path, *extra) as log:
        robots = _robots(router, ",".join(names), timeout=0.3)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            w0 = time.perf_counter()
            res = av.simulate(_drive(robots), t_final=2.5, dt=0.05, realtime=1.0,
                              log=["fleet.pose", "fleet.fresh"], progress=False)
            wall = time.perf_counter() - w0
        wait_for_stop(log, names)
    recs = read_log(log)
    # the run went to its end, on time (no crash, no stall)
    assert res.t[-1] == pytest.approx(2.5) and len(res.t) == 51
    assert wall < 2.5 + 2.0
    assert np.isfinite(res["fleet.pose"]).all()
    # counted per topic, warned with robot and topic, first in the run, once more at the end
    bad = robots.malformed
    assert sorted(bad) == sorted(f"tb{k + 1}/odom" for k in range(len(KINDS)))
    assert all(c > 0 for c in bad.values())
    msgs = [str(w.message) for w in caught if issubclass(w.category, RobotWarning)]
    for k, kind in enumerate(KINDS):
        nm = f"tb{k + 1}"
        mine = [m for m in msgs if f"'{nm}'" in m and f"'{nm}/odom'" in m]
        assert len(mine) == 2, (nm, msgs)
        assert "so far" in mine[0] and "in this run" in mine[1]
        expect = {"huge": "max_payload", "nan": "non-finite x", "inf": "non-finite y"}
        assert expect.get(kind, "not a nav_msgs/msg/Odometry") in mine[0]
    assert not [m for m in msgs if "'tb0'" in m]
    # the silent robots were zeroed by the watchdog within timeout + a step or two
    # of their first bad payload, and stayed zero; tb0 drove on
    assert sorted(e[1] for e in robots.events) == sorted(names[1:])
    assert all(e[2] == "stale" for e in robots.events)
    for nm in names[1:]:
        t_bad = _events(recs, "corrupt", nm)[0]["wall"]
        after = [c for c in commands(recs, nm) if c["wall"] > t_bad + 0.6]
        assert after and all(c["v"] == 0.0 for c in after), nm
    assert res["fleet.fresh"][-1].tolist() == [True] + [False] * len(KINDS)
    late0 = [c for c in commands(recs, "tb0") if c["wall"] > _events(recs, "corrupt")[0]["wall"]]
    assert sum(c["v"] == 0.2 for c in late0) >= 20


def test_a_robot_sending_only_garbage_fails_preflight_with_the_reason(router, tmp_path):
    from avblocks.interfaces.ros2 import PreflightError, RobotWarning
    # corrupt from the first command: the emulator needs one command to start
    # its clock, so a first robot drives it; tb2 is garbage from then on
    with emulator(router, "tb1,tb2", tmp_path, "--corrupt", "tb2@0:nan",
                  "--pose0", "[[0,0,0],[0,1,0]]"):
        from avblocks.interfaces.ros2 import _msgs
        from avblocks.interfaces.ros2._zenoh import Link
        link = Link(router)
        pub = link.publisher("tb1/cmd_vel", _msgs.TWIST)
        time.sleep(0.3)
        pub.put(_msgs.encode_twist([0, 0, 0], [0, 0, 0]))
        time.sleep(0.3)
        link.close()
        robots = _robots(router, "tb2", wait=1.0)
        with pytest.raises(PreflightError) as e, pytest.warns(RobotWarning, match="'tb2/odom'"):
            av.simulate(_drive(robots), t_final=0.5, dt=0.05, realtime=1.0, progress=False)
    assert "tb2" in str(e.value) and "malformed" in str(e.value)
    assert "non-finite x" in str(e.value)


# ------------------------------------------------------------------ dead process
def test_sigkilled_commander_robots_stop_by_their_own_command_timeout(router, tmp_path):
    with emulator(router, "tb1,tb2,tb3", tmp_path, "--rate", 50, "--cmd-timeout", 0.4,
                  "--pose0", "[[0,0,0],[0,1,0],[0,2,0]]") as log:
        p = _fleet_process(router, "tb1,tb2,tb3")
        try:
            for nm in ("tb1", "tb2", "tb3"):
                _wait_moving(log, nm)
            time.sleep(0.5)
            t_kill = time.time()
            p.send_signal(signal.SIGKILL)
            p.wait(10)
        finally:
            if p.poll() is None:
                p.kill()
        time.sleep(1.2)
    recs = read_log(log)
    for nm in ("tb1", "tb2", "tb3"):
        got = commands(recs, nm)
        assert got[-1]["v"] == 0.2              # nobody sent it a stop: the process died
        out = [e for e in _events(recs, "timeout", nm) if e["wall"] > t_kill - 0.1]
        assert len(out) == 1, (nm, out)
        assert out[0]["wall"] - t_kill < 0.5    # stopped by its own timeout
        # 0.4 s after the last command it received, to one emulator tick (20 ms)
        assert out[0]["t"] - out[0]["last_cmd"] == pytest.approx(0.4, abs=0.06)


# ------------------------------------------------------------------ two commanders
def test_a_second_process_commanding_the_same_robots_refuses_at_preflight(router, tmp_path):
    from avblocks.interfaces.ros2 import PreflightError
    with emulator(router, "tb1,tb2,tb3", tmp_path, "--pose0",
                  "[[0,0,0],[0,1,0],[0,2,0]]") as log:
        first = _fleet_process(router, "tb1,tb2")
        try:
            _wait_moving(log, "tb2")
            t_second = time.time()
            with pytest.raises(PreflightError) as e:
                av.simulate(_drive(_robots(router, "tb2,tb3"), v=0.05), t_final=0.5,
                            dt=0.05, realtime=1.0, progress=False)
            t_done = time.time()
            msg = str(e.value)
            assert "['tb2']" in msg and "tb3" not in msg.split("already")[0]
            assert "another avblocks process" in msg
            time.sleep(0.3)
            recs = read_log(log)
            # the refused run sent nothing at all: tb3 heard nobody, tb2 only the first
            assert commands(recs, "tb3") == []
            during = [c for c in commands(recs, "tb2") if t_second <= c["wall"] <= t_done + 0.3]
            assert during and all(c["v"] == 0.2 for c in during)
        finally:
            first.kill()
            first.wait(10)
        # once the first process is gone, its claim goes with it
        time.sleep(0.5)
        robots = _robots(router, "tb2,tb3")
        av.simulate(_drive(robots, v=0.05), t_final=0.3, dt=0.05, realtime=1.0,
                    progress=False)
        wait_for_stop(log, ("tb3",))
    assert any(c["v"] == 0.05 for c in commands(read_log(log), "tb3"))


# ------------------------------------------------------------------ router restart
def test_router_restart_mid_run_the_run_resumes(tmp_path):
    _need("zenoh")
    from avblocks.interfaces.ros2 import free_port
    ep = f"tcp/127.0.0.1:{free_port()}"
    routers = [_router_process(ep)]
    timeline = {}
    try:
        with emulator(ep, "tb1,tb2", tmp_path, "--rate", 50, "--cmd-timeout", 0.4,
                      "--pose0", "[[0,0,0],[0,1,0]]") as log:

            def outage():
                timeline["moving"] = _wait_moving(log, "tb1")
                time.sleep(1.0)
                timeline["kill"] = time.time()
                routers[0].kill()
                routers[0].wait(10)
                time.sleep(1.5)
                timeline["back"] = time.time()
                routers.append(_router_process(ep))

            th = threading.Thread(target=outage, daemon=True)
            th.start()
            robots = _robots(ep, "tb1,tb2", timeout=0.3, give_up=10.0)
            w0 = time.perf_counter()
            # 10 s: the Zenoh peers' reconnection back-off after the router's
            # return took more than the 3 s that 7 s left, in a loaded CI run
            res = av.simulate(_drive(robots), t_final=10.0, dt=0.05, realtime=1.0,
                              log=["fleet.fresh"], progress=False)
            wall = time.perf_counter() - w0
            th.join(10)
            wait_for_stop(log, ("tb1", "tb2"))
    finally:
        for r in routers:
            r.kill()
            r.wait(10)
    recs = read_log(log)
    assert res.t[-1] == pytest.approx(10.0) and wall < 10.0 + 2.0
    for nm in ("tb1", "tb2"):
        # stale while the router was away, fresh again after it came back
        assert [e[2] for e in robots.events if e[1] == nm] == ["stale", "fresh"]
        # the robot stopped by its own timeout during the outage ...
        out = [e for e in _events(recs, "timeout", nm)
               if timeline["kill"] < e["wall"] < timeline["back"]]
        assert len(out) == 1 and out[0]["wall"] - timeline["kill"] < 0.5
        # ... and drove again once the router was back; the run's end stopped it
        again = [c for c in commands(recs, nm) if c["wall"] > timeline["back"] and c["v"] > 0]
        assert len(again) >= 10
        assert commands(recs, nm)[-1]["v"] == 0.0
    assert res["fleet.fresh"][-1].all() and not res["fleet.fresh"].all()


def test_router_gone_for_good_stops_and_ends_the_run_with_its_log(tmp_path):
    _need("zenoh")
    from avblocks.interfaces.ros2 import RobotLinkError, free_port
    ep = f"tcp/127.0.0.1:{free_port()}"
    r = _router_process(ep)
    timeline = {}
    try:
        with emulator(ep, "tb1,tb2", tmp_path, "--rate", 50, "--cmd-timeout", 0.4,
                      "--pose0", "[[0,0,0],[0,1,0]]") as log:

            def outage():
                _wait_moving(log, "tb1")
                time.sleep(0.8)
                timeline["kill"] = time.time()
                r.kill()

            th = threading.Thread(target=outage, daemon=True)
            th.start()
            w0 = time.perf_counter()
            with pytest.raises(RobotLinkError) as e:
                av.simulate(_drive(_robots(ep, "tb1,tb2", give_up=1.0)), t_final=30.0,
                            dt=0.05, realtime=1.0, log=["fleet.pose", "fleet.age"],
                            progress=False)
            t_end = time.time()
            wall = time.perf_counter() - w0
            th.join(10)
            time.sleep(0.3)
    finally:
        r.kill()
        r.wait(10)
    recs = read_log(log)
    assert wall < 6.0                               # not the 30 s of the run, no hang
    assert 1.0 <= t_end - timeline["kill"] < 2.5    # give_up after the last pose
    assert "no pose from any robot" in str(e.value)
    res = e.value.results
    assert res is not None and res.t[-1] > 0.8 and res["fleet.age"][-1].min() > 0.9
    for nm in ("tb1", "tb2"):
        out = [x for x in _events(recs, "timeout", nm) if x["wall"] > timeline["kill"]]
        assert len(out) == 1 and out[0]["wall"] - timeline["kill"] < 0.5


def test_cli_run_gives_up_on_silent_robots_stops_and_saves_results(router, tmp_path):
    from avblocks.core.results import Results

    from .test_ros2_formation import SCALE, _cli, _pose0
    out = tmp_path / "out"
    with emulator(router, "tb1,tb2,tb3", tmp_path, "--pose0", _pose0(), "--time-scale",
                  SCALE) as log:
        p = subprocess.Popen(_cli(router, out, 120, "--robot-give-up", 4), env=env(),
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        for nm in ("tb1", "tb2", "tb3"):
            _wait_moving(log, nm, timeout=30)
        time.sleep(0.5)
    t_gone = time.monotonic()           # the emulator (every robot) is gone
    stdout, stderr = p.communicate(timeout=30)
    waited = time.monotonic() - t_gone
    assert p.returncode == 3, stderr                # the run failed, results saved
    assert "no pose from any robot" in stderr and "give_up=4" in stderr
    assert 0.9 < waited < 10                        # 4 robot s = 1 wall s at 4x
    res = Results.load(out / "results.nc")
    assert 0 < res.t[-1] < 120 and np.isfinite(res["fleet.pose"]).all()
