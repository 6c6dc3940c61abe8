"""Flying safely with Crazyflies, against the emulator (a subprocess) over a
real Zenoh router on loopback: pre-flight refusals naming each vehicle and
its reason; a stale pose, a vehicle gone silent, Ctrl-C and SIGTERM each
end with every vehicle landed (the one gone silent falls by the firmware's
own set-point watchdog) and the logs kept; a SIGKILLed commander leaves
every vehicle to that watchdog. What happened is read from the emulator's
log (the vehicles' side) and the block's flight log."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import avblocks as av

from ._cf import SOFT_TOUCHDOWN, cf_emulator, events, read_log, wait_for
from .conftest import env

HERE = Path(__file__).resolve().parent
NAMES = ("cf1", "cf2", "cf3")
P0 = "[[0, 0, 0], [0, 1, 0], [0, 2, 0]]"


def _drive(router, names=NAMES, v=(0.1, 0.0, 0.0), **kw):
    from avblocks.interfaces.crazyflie import Crazyflies
    d = av.Diagram()
    c = d.add(av.blocks.Constant(np.tile(v, (len(names), 1))), name="c")
    f = d.add(Crazyflies(list(names), router, takeoff_height=0.5, land_duration=1.5, **kw),
              name="fleet")
    d.connect(c.y, f.velocity)
    return d, f.block


def _landed_softly(recs, names, after):
    """Each vehicle came down on its landing trajectory after ``after`` (wall):
    notify_setpoints_stop first, then land (Crazyswarm2's order; the block's end
    repeats the pair, for lossy links), nothing else; no set-point after the
    first notification (by the sender's stamps); a soft touch-down."""
    for nm in names:
        got = [e for e in events(recs, "service", nm) if e["wall"] >= after]
        srv = [e["service"] for e in got]
        assert srv[:2] == ["notify_setpoints_stop", "land"], (nm, srv)
        assert set(srv) == {"land", "notify_setpoints_stop"}, (nm, srv)
        # the arguments as the emulator decoded them: to 0.03 m (a float32) in
        # 1.5 s, all groups
        assert got[1]["request"] == {"group_mask": 0, "height": float(np.float32(0.03)),
                                     "duration": 1.5}
        assert got[0]["request"] == {"group_mask": 0, "remain_valid_millisecs": 100}
        # every set-point was sent before the notification arrived (the sender's
        # stamp; the emulator's subscriber and queryable run on different Zenoh
        # threads, so on a loaded machine one sent just before the notification
        # can be read just after it, as by Crazyswarm2's server)
        assert all(s["stamp"] < got[0]["wall"] for s in events(recs, "setpoint", nm)
                   if s["accepted"])
        assert events(recs, "landing_cancelled", nm) == []
        (g,) = [e for e in events(recs, "ground", nm) if e["wall"] >= after]
        assert g["mode"] in ("hl", "drop") and g["speed"] < SOFT_TOUCHDOWN, (nm, g)
        assert events(recs, "wdt_level_out", nm) == []


def _all_down(names):
    return lambda r: all(events(r, "ground", nm) for nm in names)


def test_preflight_refusals_name_each_vehicle_and_the_reason(router, tmp_path):
    from avblocks.interfaces.flight import PreflightError
    with cf_emulator(router, "cf1,cf2,cf3", tmp_path, "--position0",
                     "[[0, 0, 0], [0.3, 0, 0], [3, 0, 0]]", "--battery", "cf1=3.5") as log:
        d, fleet = _drive(router, ("cf1", "cf2", "cf3", "cf4"), wait=2.0,
                          geofence=(-1, 2, -1, 1, -0.1, 2), min_separation=0.5,
                          log=str(tmp_path / "flight.jsonl"))
        with pytest.raises(PreflightError) as e:
            av.simulate(d, t_final=1.0, dt=0.05, realtime=1.0, progress=False)
        time.sleep(0.3)
    msg = str(e.value)
    assert "cf4: does not answer" in msg
    # 3.5 V on the firmware's LiPo curve: 0.1 * (3.5 - 3.0) / (3.78 - 3.0) = 6 %
    assert "cf1: battery low (6 % < battery_min 20 %)" in msg
    assert "cf3 at (3.00, 0.00, 0.00) is outside the geofence" in msg
    assert "cf1-cf2 0.30 m apart (min_separation 0.5 m)" in msg
    assert "cf2:" not in msg.replace("cf1-cf2", "")
    recs = read_log(log)
    assert events(recs, "service") == [] and events(recs, "setpoint") == []
    flight = [json.loads(s) for s in (tmp_path / "flight.jsonl").read_text().splitlines()]
    assert [r["ev"] for r in flight if r["ev"] == "preflight_refused"] == ["preflight_refused"]


def test_a_stale_pose_lands_every_vehicle_and_ends_the_run_with_its_log(router, tmp_path):
    from avblocks.interfaces.flight import FailsafeError
    with cf_emulator(router, ",".join(NAMES), tmp_path, "--position0", P0,
                     "--stale", "cf2@1.0") as log:
        # stale_timeout above the status period (0.5 s): the vehicle is heard, so
        # the flight layer calls its missing poses stale, not silent (and above the
        # half second a loaded machine can hold every pose back)
        d, fleet = _drive(router, stale_timeout=1.2, log=str(tmp_path / "flight.jsonl"))
        with pytest.raises(FailsafeError) as e:
            av.simulate(d, t_final=30.0, dt=0.05, realtime=1.0, log=["fleet.position"],
                        progress=False)
        recs = wait_for(log, _all_down(NAMES), timeout=15)
    assert e.value.reason == "stale" and e.value.vehicles == ["cf2"]
    res = e.value.results
    assert res is not None and 1.0 < res.t[-1] < 5.0
    t_stale = events(recs, "stale", "cf2")[0]["wall"]
    # cf2 still answers its services: it lands like the others
    _landed_softly(recs, NAMES, after=t_stale)
    flight = [json.loads(s) for s in (tmp_path / "flight.jsonl").read_text().splitlines()]
    (fs,) = [r for r in flight if r["ev"] == "failsafe"]
    assert fs["reason"] == "stale" and fs["vehicles"] == ["cf2"]
    # the pose age passed stale_timeout (1.2 s): its last pose came up to one pose
    # period (20 ms) before the emulator logged "stale"
    assert 1.2 - 0.025 < fs["wall"] - t_stale < 2.0
    assert flight[-1]["ev"] == "end"


def test_a_vehicle_gone_silent_lands_the_others_and_falls_by_its_own_watchdog(
        router, tmp_path):
    from avblocks.interfaces.flight import FailsafeError
    with cf_emulator(router, ",".join(NAMES), tmp_path, "--position0", P0,
                     "--silent", "cf2@1.0") as log:
        # link_timeout 1 s: a loaded machine can hold every pose back for half a second
        d, fleet = _drive(router, stale_timeout=5.0, link_timeout=1.0,
                          log=str(tmp_path / "flight.jsonl"))
        with pytest.raises(FailsafeError) as e:
            av.simulate(d, t_final=30.0, dt=0.05, realtime=1.0, progress=False)
        recs = wait_for(log, _all_down(NAMES), timeout=15)
    assert e.value.reason == "silent" and e.value.vehicles == ["cf2"]
    assert e.value.results is not None
    t_gone = events(recs, "silent", "cf2")[0]["wall"]
    _landed_softly(recs, ("cf1", "cf3"), after=t_gone)
    # cf2 heard nothing after it went silent: its firmware levelled it out 0.5 s
    # after its last set-point, stopped the motors at 2 s, and it fell
    assert [x for x in events(recs, "service", "cf2") if x["wall"] > t_gone] == []
    last = [s for s in events(recs, "setpoint", "cf2") if s["wall"] <= t_gone][-1]["t"]
    (lv,) = events(recs, "wdt_level_out", "cf2")
    (off,) = events(recs, "wdt_motors_off", "cf2")
    (g,) = events(recs, "ground", "cf2")
    assert 0.5 < lv["age"] <= 0.521 and 2.0 < off["age"] <= 2.021      # physics clock
    # the wall clock, loosely: a set-point's line is written a little after
    # the firmware stamped it (up to tens of ms on a loaded machine)
    assert 0.45 < lv["t"] - last < 0.8 and 1.95 < off["t"] - last < 2.3
    assert g["mode"] == "falling" and g["speed"] > 2.0


def _commander(router, tmp_path):
    flight, results = tmp_path / "flight.jsonl", tmp_path / "results.nc"
    p = subprocess.Popen([sys.executable, str(HERE / "_cf_fleet_run.py"), router,
                          ",".join(NAMES), "60", str(flight), str(results)], env=env(),
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    return p, flight, results


def _wait_started(p):
    t_end = time.monotonic() + 40
    while time.monotonic() < t_end:
        line = p.stdout.readline()
        if "started" in line:
            return
        if not line and p.poll() is not None:
            break
    raise AssertionError(f"commander did not start: {p.stdout.read()}")


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["ctrl-c", "sigterm"])
def test_ctrl_c_and_sigterm_land_every_vehicle_and_save_the_logs(router, tmp_path, sig):
    from avblocks.core.results import Results
    with cf_emulator(router, ",".join(NAMES), tmp_path, "--position0", P0) as log:
        p, flight, results = _commander(router, tmp_path)
        try:
            _wait_started(p)
            time.sleep(1.0)
            t_sig = time.time()
            p.send_signal(sig)
            out, _ = p.communicate(timeout=30)
        finally:
            if p.poll() is None:
                p.kill()
        recs = wait_for(log, _all_down(NAMES), timeout=15)
    assert "saved" in out, out
    _landed_softly(recs, NAMES, after=t_sig)
    res = Results.load(results)
    assert 0.8 < res.t[-1] < 10 and np.isfinite(res["fleet.position"]).all()
    fl = [json.loads(s) for s in flight.read_text().splitlines()]
    fs = [r for r in fl if r["ev"] == "failsafe"]
    assert fs and fs[0]["reason"] == "signal or exit" and fs[0]["wall"] - t_sig < 0.5
    assert fl[-1]["ev"] == "end"


def test_sigkill_leaves_every_vehicle_to_the_firmware_watchdog(router, tmp_path):
    with cf_emulator(router, ",".join(NAMES), tmp_path, "--position0", P0) as log:
        p, flight, _ = _commander(router, tmp_path)
        try:
            _wait_started(p)
            time.sleep(1.0)
            t_kill = time.time()
            p.send_signal(signal.SIGKILL)
            p.wait(10)
        finally:
            if p.poll() is None:
                p.kill()
        recs = wait_for(log, _all_down(NAMES), timeout=15)
    for nm in NAMES:
        assert [x for x in events(recs, "service", nm) if x["wall"] > t_kill] == []
        last = events(recs, "setpoint", nm)[-1]
        assert last["wall"] <= t_kill + 0.05
        (lv,) = events(recs, "wdt_level_out", nm)
        (off,) = events(recs, "wdt_motors_off", nm)
        (g,) = events(recs, "ground", nm)
        assert 0.5 < lv["age"] <= 0.521 and 2.0 < off["age"] <= 2.021
        # the ages count from the last set-point's stamp (physics clock) ...
        assert off["at"] - last["at"] == pytest.approx(off["age"], abs=1e-5)
        # ... and the wall clock agrees loosely (a line is written a little
        # after its event: tens of ms on a loaded machine)
        assert 0.45 < lv["t"] - last["t"] < 0.8 and 1.95 < off["t"] - last["t"] < 2.3
        assert g["mode"] == "falling"
    # the flight log up to the kill is on disk (written and flushed as it happened)
    fl = [json.loads(s) for s in flight.read_text().splitlines()]
    assert any(r["ev"] == "phase" and r["phase"] == "mission" for r in fl)
    assert sum(r["ev"] == "cmd" for r in fl) >= 15


def test_a_second_commander_of_the_same_vehicles_is_refused_before_sending(router, tmp_path):
    from avblocks.interfaces.flight import PreflightError
    with cf_emulator(router, ",".join(NAMES), tmp_path, "--position0", P0) as log:
        p, _, _ = _commander(router, tmp_path)
        try:
            _wait_started(p)
            n_before = len(read_log(log))
            d, _ = _drive(router, ("cf3",), wait=2.0)
            t0 = time.time()
            with pytest.raises(PreflightError) as e:
                av.simulate(d, t_final=1.0, dt=0.05, realtime=1.0, progress=False)
            t1 = time.time()
        finally:
            p.send_signal(signal.SIGTERM)
            p.communicate(timeout=30)
    assert "['cf3'] are already commanded by another avblocks process" in str(e.value)
    recs = read_log(log)
    assert n_before > 0
    # nothing from the refused run: cf3's services are the first commander's only
    # (its takeoff before, its landing after the SIGTERM), no set-point but 0.1 m/s
    assert [x["service"] for x in events(recs, "service", "cf3")
            if t0 <= x["wall"] <= t1] == []
    assert all(s["vel"] == [0.1, 0.0, 0.0] for s in events(recs, "setpoint", "cf3"))


def test_a_nan_command_lands_every_vehicle_and_logs_each_confirmation(router, tmp_path):
    """A NaN in the commands: the fail-safe lands every vehicle (notify, then
    land), every service call is answered in the flight log (one NaN run had
    logged a notify as "no reply" that the emulator had received: two threads
    read one reply channel) and each vehicle's landing is confirmed in it."""
    from avblocks.interfaces.crazyflie import Crazyflies
    from avblocks.interfaces.flight import FailsafeError
    flight = tmp_path / "flight.jsonl"
    with cf_emulator(router, ",".join(NAMES), tmp_path, "--position0", P0) as log:
        d = av.Diagram()
        f = d.add(Crazyflies(list(NAMES), router, takeoff_height=0.5, land_duration=1.5,
                             log=str(flight)), name="fleet")
        law = d.add(av.blocks.Function(
            lambda t, p: np.where(t >= 1.0, np.nan, 0.1) * np.ones((3, 3)),
            inputs={"p": (3, 3)}, outputs={"v": (3, 3)}), name="law")
        d.connect(f.position, law.p)
        d.connect(law.v, f.velocity)
        with pytest.raises(FailsafeError) as e:
            av.simulate(d, t_final=10.0, dt=0.05, realtime=1.0, progress=False)
        recs = wait_for(log, _all_down(NAMES), timeout=15)
    assert e.value.reason == "nan" and e.value.vehicles == list(NAMES)
    fl = [json.loads(s) for s in flight.read_text().splitlines()]
    t_fs = [r for r in fl if r["ev"] == "failsafe"][0]["wall"]
    _landed_softly(recs, NAMES, after=t_fs - 0.5)
    sent = [r for r in fl if r["ev"] == "land_sent"]
    assert sent and all(r["unanswered"] == [] for r in sent), sent
    assert sent[0]["order"] == ["notify_setpoints_stop", "land"]
    landed = {r["vehicle"]: r for r in fl if r["ev"] == "landed"}
    assert sorted(landed) == list(NAMES)
    assert all(r["position"][2] < 0.05 and 1.0 < r["after_s"] < 4.0 for r in landed.values())
    assert [r for r in fl if r["ev"] in ("land_timeout", "land_unconfirmed")] == []
    assert fl[-1]["ev"] == "end"
