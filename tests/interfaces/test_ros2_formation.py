"""Case study IV.D on (emulated) robots: ``avblocks run formation --robots
tb1,tb2,tb3`` swaps the unicycle block for the ROS 2 block and changes
nothing else. The emulator and the run are subprocesses talking over real
Zenoh on loopback; the emulated world and the paced run both go 4x faster
than the wall clock (the physics is the same, only the clock is scaled).
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

import avblocks as av
from avblocks.core.results import Results
from avblocks.scenarios import formation

from .conftest import commands, emulator, env, read_log

SCALE = 4.0
SETS = ["--set", "agents=3", "--set", "dt=0.05", "--set", "log_every=2"]


def _pose0():
    d, _ = formation.make_diagram(followers=2, dt=0.05, log_every=2)
    return json.dumps(d["fleet"].block.initial_state()["pose"].tolist())


def _cli(router, out, t_final, *extra):
    return [sys.executable, "-m", "avblocks", "run", "formation", "--robots", "tb1,tb2,tb3",
            "--router", router, *SETS, "--t-final", str(t_final), "--realtime", str(SCALE),
            "--out", str(out), "--quiet", *map(str, extra)]


def _run(router, tmp_path, t_final, emu=(), extra=()):
    with emulator(router, "tb1,tb2,tb3", tmp_path, "--pose0", _pose0(), "--time-scale",
                  SCALE, *emu) as log:
        p = subprocess.run(_cli(router, tmp_path / "out", t_final, *extra), env=env(),
                           capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    return Results.load(tmp_path / "out" / "results.nc"), read_log(log), p.stdout


def _measures(r):
    m = r["supervisor.mode"].astype(int)
    switches = r.t[np.nonzero(np.diff(m))[0] + 1]
    el = np.abs(r["lf.error"][:, 1:, 0])              # distance errors of the followers
    P = r["fleet.pose"][:, :, :2]
    dist = np.linalg.norm(P[:, :, None] - P[:, None], axis=-1) + 1e9 * np.eye(P.shape[1])
    return switches, float(np.sqrt((el ** 2).mean())), el, float(dist.min())


def _reference(t_final):
    d, sim = formation.make_diagram(followers=2, dt=0.05, log_every=2)
    sim["t_final"] = t_final
    return av.simulate(d, **sim)


@pytest.mark.slow
def test_clean_network_matches_the_simulated_run(router, tmp_path):
    res, recs, out = _run(router, tmp_path, 66)
    sw_s, rms_s, _, dmin_s = _measures(_reference(66))
    sw_r, rms_r, _, dmin_r = _measures(res)
    assert len(sw_s) == len(sw_r) == 2
    assert np.all(np.abs(sw_r - sw_s) <= 0.1 * sw_s)
    assert abs(rms_r - rms_s) <= 0.1 * rms_s + 0.01
    assert not res["collision.hit_agent"].any() and not res["collision.hit_obstacle"].any()
    assert "steps overran, worst lateness" in out
    assert all(commands(recs, r)[-1]["v"] == 0 for r in ("tb1", "tb2", "tb3"))


@pytest.mark.slow
def test_lossy_slow_network_still_converges_without_collision(router, tmp_path):
    # 30 % of the messages lost in each direction, 100 ms each way (200 ms
    # round trip) plus up to 20 ms jitter
    res, recs, _ = _run(router, tmp_path, 45,
                        emu=["--loss", 0.3, "--latency", 0.1, "--jitter", 0.02])
    sw_s, rms_s, _, _ = _measures(_reference(45))
    sw, rms, el, dmin = _measures(res)
    # the switch to the column happens at nearly the same time
    assert len(sw) == 1 and np.all(np.abs(sw - sw_s) <= 0.1 * sw_s)
    # the delay costs accuracy, but the error stays bounded (spacing 1.5 m)
    i0, i1 = np.searchsorted(res.t, [10, sw[0]])     # settled wedge
    j0, j1 = np.searchsorted(res.t, [33, 45])        # settled column, in the corridor
    for a, b in ((i0, i1), (j0, j1)):
        assert np.sqrt((el[a:b] ** 2).mean()) < 0.3 and el[a:b].max() < 0.75
    assert dmin > 0.5
    assert not res["collision.hit_agent"].any() and not res["collision.hit_obstacle"].any()
    assert sum(c["lost"] for c in commands(recs)) > 0.2 * len(commands(recs))


def test_silenced_robot_is_stopped_within_half_a_second(router, tmp_path):
    res, recs, _ = _run(router, tmp_path, 16, emu=["--drop", "tb2@8"],
                        extra=["--robot-timeout", 0.3])
    t_drop = [r for r in recs if r["ev"] == "drop"][0]["t"]
    zero = min(c["t"] for c in commands(recs, "tb2") if c["t"] > t_drop and c["v"] == 0
               and c["w"] == 0)
    assert zero - t_drop < 0.5                    # robot seconds, on the emulator's side
    after = [c for c in commands(recs, "tb2") if c["t"] >= zero]
    assert all(c["v"] == 0 and c["w"] == 0 for c in after)
    for r in ("tb1", "tb3"):
        moving = [c for c in commands(recs, r) if zero + 1 < c["t"] < zero + 5]
        assert moving and np.mean([c["v"] > 0.1 for c in moving]) > 0.9
    assert res.t[-1] == pytest.approx(16.0)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signal_mid_run_stops_every_robot_and_saves_results(router, tmp_path, sig):
    out = tmp_path / "out"
    with emulator(router, "tb1,tb2,tb3", tmp_path, "--pose0", _pose0(), "--time-scale",
                  SCALE) as log:
        p = subprocess.Popen(_cli(router, out, 60), env=env(), stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
        t_end = time.monotonic() + 30
        while time.monotonic() < t_end:
            moving = {c["robot"] for c in commands(read_log(log)) if c["v"] > 0}
            if len(moving) == 3:
                break
            time.sleep(0.1)
        time.sleep(1.0)
        t_sig = time.time()
        p.send_signal(sig)
        stdout, stderr = p.communicate(timeout=30)
        time.sleep(0.3)
        recs = read_log(log)
    assert p.returncode == 128 + sig, stderr          # the CLI's convention
    for r in ("tb1", "tb2", "tb3"):
        last = commands(recs, r)[-1]
        assert last["v"] == 0 and last["w"] == 0 and last["wall"] > t_sig
    res = Results.load(out / "results.nc")
    assert res.meta.get("interrupted") and 0 < res.t[-1] < 60
    assert "interrupted" in stdout
