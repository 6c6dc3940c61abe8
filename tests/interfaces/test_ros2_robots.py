"""The Robots block against the robot emulator (a subprocess) over real
Zenoh on loopback: motion against the analytic unicycle arc, command
limits, watchdog, emergency stop, pre-flight, and zero velocity on every
way a run ends."""

from __future__ import annotations

import numpy as np
import pytest

import avblocks as av

from .conftest import commands, emulator, read_log, wait_for_stop


def _robots(router, names="tb1,tb2", **kw):
    from avblocks.interfaces.ros2 import Robots
    return Robots(names.split(","), router=router, **kw)


def _const(d, cmd, robots, name="c"):
    c = d.add(av.blocks.Constant(np.asarray(cmd, float)), name=name)
    f = d.add(robots, name="fleet")
    d.connect(c.y, f.port(robots.cmd_port))
    return f


def test_unicycle_follows_the_arc_and_stops_at_the_end(router, tmp_path):
    p0 = [[0.0, 0.0, 0.0], [2.0, 1.0, np.pi / 2]]
    v, w = 0.5, 0.4
    with emulator(router, "tb1,tb2", tmp_path, "--pose0", str(p0), "--rate", 50) as log:
        d = av.Diagram()
        _const(d, [[v, w], [v, 0.0]], _robots(router))
        res = av.simulate(d, t_final=2.0, dt=0.05, realtime=1.0,
                          log=["fleet.pose", "fleet.fresh", "fleet.age"])
        wait_for_stop(log, ("tb1", "tb2"))
    recs = read_log(log)
    assert res["fleet.fresh"][1:].all()
    assert np.median(res["fleet.age"][1:]) < 0.1   # 50 Hz odometry (slack for a busy machine)
    # what the robots received: the command, and zero at the end of the run
    for r in ("tb1", "tb2"):
        got = commands(recs, r)
        assert got[-1]["v"] == 0.0 and got[-1]["w"] == 0.0
    moving = [c for c in commands(recs, "tb1") if c["v"] > 0]
    assert moving[0]["v"] == v and moving[0]["w"] == w
    # emulator's final pose vs the exact arc over the time it drove
    end = [r for r in recs if r["ev"] == "end"][0]["poses"]
    tb1 = np.array(end[0])
    theta = tb1[3]                      # = w * T_driven
    T = theta / w
    expect = [v / w * np.sin(w * T), v / w * (1 - np.cos(w * T))]
    assert tb1[:2] == pytest.approx(expect, abs=1e-6)
    assert 1.7 < T < 2.3                # it drove for about the run's length
    tb2 = np.array(end[1])              # straight up from (2, 1)
    assert tb2[0] == pytest.approx(2.0, abs=1e-9) and tb2[3] == pytest.approx(np.pi / 2)
    assert 1.0 + 0.5 * 1.7 < tb2[1] < 1.0 + 0.5 * 2.3
    # the block's last pose output is the pose the robot had then
    assert res["fleet.pose"][-1, 0, 2] == pytest.approx(theta, abs=0.06)


def test_limits_are_enforced_before_sending(router, tmp_path):
    with emulator(router, "tb1", tmp_path) as log:
        d = av.Diagram()
        _const(d, [[5.0, -9.0]], _robots(router, "tb1", v_max=0.3, omega_max=1.2))
        av.simulate(d, t_final=0.5, dt=0.05, realtime=1.0)
    got = [c for c in commands(read_log(log)) if c["v"] != 0]
    assert got and all(c["v"] == 0.3 and c["w"] == -1.2 for c in got)


def test_preflight_names_missing_far_and_close_robots(router, tmp_path):
    from avblocks.interfaces.ros2 import PreflightError
    p0 = [[0.0, 0.0, 0.0], [0.2, 0.0, 0.0], [9.0, 0.0, 0.0]]
    with emulator(router, "tb1,tb2,tb3", tmp_path, "--pose0", str(p0)) as log:
        for kw, words in (({"names": "tb1,tb9", "wait": 0.5}, ["tb9"]),
                          ({"names": "tb1,tb3", "arena": (-1, 5, -1, 1)}, ["tb3", "arena"]),
                          ({"names": "tb1,tb2,tb3", "min_distance": 0.5},
                           ["tb1-tb2", "0.20 m"])):
            names = kw.pop("names")
            d = av.Diagram()
            _const(d, np.ones((len(names.split(",")), 2)), _robots(router, names, **kw))
            with pytest.raises(PreflightError) as e:
                av.simulate(d, t_final=0.2, dt=0.05, realtime=1.0)
            for w in words:
                assert w in str(e.value)
    # nothing but zeros was ever commanded
    assert all(c["v"] == 0 and c["w"] == 0 for c in commands(read_log(log)))


def test_watchdog_zeroes_a_silent_robot_and_the_others_keep_going(router, tmp_path):
    with emulator(router, "tb1,tb2", tmp_path, "--drop", "tb2@1.0",
                  "--pose0", "[[0,0,0],[0,2,0]]") as log:
        d = av.Diagram()
        robots = _robots(router, timeout=0.3)
        _const(d, [[0.2, 0.0], [0.2, 0.0]], robots)
        res = av.simulate(d, t_final=2.5, dt=0.05, realtime=1.0,
                          log=["fleet.pose", "fleet.fresh"])
    recs = read_log(log)
    t_drop = [r for r in recs if r["ev"] == "drop"][0]["wall"]
    first_zero = min(c["wall"] for c in commands(recs, "tb2")
                     if c["wall"] > t_drop and c["v"] == 0)
    assert first_zero - t_drop < 0.5
    late = [c for c in commands(recs, "tb2") if c["wall"] > first_zero]
    assert late and all(c["v"] == 0 for c in late)
    ok = [c for c in commands(recs, "tb1") if t_drop < c["wall"] < first_zero + 0.5]
    assert ok and all(c["v"] == 0.2 for c in ok)
    fresh = res["fleet.fresh"]
    assert fresh[-1].tolist() == [True, False]
    held = res["fleet.pose"][-10:, 1]
    assert np.ptp(held[:, 0]) == 0.0    # tb2's output is held
    assert [e[1:] for e in robots.events] == [("tb2", "stale")]


def test_estop_input_and_latched_emergency_stop(router, tmp_path):
    with emulator(router, "tb1,tb2", tmp_path) as log:
        d = av.Diagram()
        robots = _robots(router, estop=True)
        f = _const(d, [[0.3, 0.0], [0.3, 0.0]], robots)
        stop = d.add(av.blocks.Constant(np.array([False, True])), name="stop")
        d.connect(stop.y, f.estop)
        av.simulate(d, t_final=0.5, dt=0.05, realtime=1.0)
    recs = read_log(log)
    assert all(c["v"] == 0 for c in commands(recs, "tb2"))
    assert any(c["v"] == 0.3 for c in commands(recs, "tb1"))


@pytest.mark.parametrize("fault", ["exception", "nan"])
def test_any_failure_stops_every_robot_and_keeps_the_log(router, tmp_path, fault):
    def cmd(t, xp):
        if t > 0.5:
            if fault == "exception":
                raise RuntimeError("controller bug")
            return np.full((2, 2), np.nan)
        return np.full((2, 2), 0.25)
    with emulator(router, "tb1,tb2", tmp_path) as log:
        d = av.Diagram()
        src = d.add(av.blocks.Function(lambda t, xp: {"y": cmd(t, xp)}, inputs={},
                                       outputs={"y": (2, 2)}), name="ctrl")
        f = d.add(_robots(router), name="fleet")
        d.connect(src.y, f.cmd)
        with pytest.raises(av.AvError) as e:
            av.simulate(d, t_final=2.0, dt=0.05, realtime=1.0)
        assert ("ctrl" in str(e.value)) if fault == "exception" else ("cmd" in str(e.value))
        assert e.value.results is not None and e.value.results.t[-1] >= 0.5
    for r in ("tb1", "tb2"):
        got = commands(read_log(log), r)
        assert any(c["v"] == 0.25 for c in got) and got[-1]["v"] == 0.0


def test_holonomic_mocap_with_frame_transform_over_rmw_zenoh(router, tmp_path):
    # the emulator's world is the mocap frame; the mocap frame sits at
    # (1, -1) rotated by 90 degrees in our world
    with emulator(router, "cf1", tmp_path, "--model", "holonomic2d", "--pose", "mocap",
                  "--transport", "rmw_zenoh", "--pose0", "[[0.5, 0, 0]]") as log:
        d = av.Diagram()
        robots = _robots(router, "cf1", kind="holonomic2d", pose="mocap",
                         transport="rmw_zenoh", mocap_transform=(1.0, -1.0, np.pi / 2))
        _const(d, [[0.0, 0.2]], robots)      # +y in our world = +x in the mocap frame
        res = av.simulate(d, t_final=1.0, dt=0.05, realtime=1.0,
                          log=["fleet.position", "fleet.velocity"])
    pos = res["fleet.position"]
    assert pos[0, 0] == pytest.approx([1.0, -0.5], abs=1e-9)     # R(90) (0.5, 0) + (1, -1)
    assert pos[-1, 0, 0] == pytest.approx(1.0, abs=1e-6)
    assert pos[-1, 0, 1] > -0.5 + 0.1
    assert res["fleet.velocity"][-3, 0] == pytest.approx([0.0, 0.2], abs=0.03)
    sent = [c for c in commands(read_log(log)) if c["v"] != 0]
    # world (0, 0.2) is body +x for a robot at yaw 0 in the mocap frame?
    # the block rotates by the yaw it sees (90 deg in our world): body = (0.2, 0)
    assert sent and sent[0]["v"] == pytest.approx(0.2) and sent[0]["vy"] == pytest.approx(0)
