"""The Crazyflie emulator (a subprocess on a real Zenoh router) behaves as
the firmware it copies (crazyflie-firmware 2026.08): the high-level
commander's 7th-order takeoff, set-points refused on the ground, the
supervisor's set-point watchdog (level out after 0.5 s, motors off after
2 s, then a free fall), the land / notify_setpoints_stop handover. Truth:
the firmware's constants, the rest-to-rest polynomial written out here,
free-fall kinematics."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from ._cf import SOFT_TOUCHDOWN, cf_emulator, events, read_log, wait_for


def _client(router):
    from avblocks.interfaces.crazyflie import _types as T
    from avblocks.interfaces.crazyflie._link import CfLink
    link = CfLink(router, node="test_commander")
    poses = {}

    def on(nm):
        def cb(data, now):
            poses.setdefault(nm, []).append((time.monotonic(), T.decode_pose(data)))
        return cb
    for nm in ("cf1", "cf2"):
        link.subscribe(f"/{nm}/pose", T.POSE_STAMPED, on(nm))
    return link, poses, T


def _airborne(link, T, duration):
    """Both vehicles taken off to 0.5 m in ``duration`` s and hovering; their
    takeoff clients and velocity publishers."""
    time.sleep(0.5)
    tk = [link.client(f"/{nm}/takeoff", T.TAKEOFF) for nm in ("cf1", "cf2")]
    assert all(c.call(height=0.5, duration=duration)[0] for c in tk)
    time.sleep(duration + 0.5)
    pubs = [link.publisher(f"/{nm}/cmd_velocity_world", T.VELOCITY_WORLD)
            for nm in ("cf1", "cf2")]
    time.sleep(0.3)
    return tk, pubs


def _poly(s):
    s = min(max(s, 0.0), 1.0)
    return 35 * s ** 4 - 84 * s ** 5 + 70 * s ** 6 - 20 * s ** 7


def test_takeoff_follows_the_high_level_commanders_polynomial_and_ground_setpoints_are_refused(
        router, tmp_path):
    with cf_emulator(router, "cf1,cf2", tmp_path, "--position0",
                     "[[0.5, 0.2, 0.0], [1.0, 0.2, 0.0]]") as log:
        link, poses, T = _client(router)
        try:
            time.sleep(0.5)
            # a set-point to a vehicle on the floor is refused and changes nothing
            pub = link.publisher("/cf2/cmd_velocity_world", T.VELOCITY_WORLD)
            time.sleep(0.3)
            for _ in range(5):
                pub.put(T.encode_velocity_world((0.0, 0.0, 0.5), 0.0, time.time()))
                time.sleep(0.05)
            assert link.client("/cf1/takeoff", T.TAKEOFF).call(height=0.6, duration=2.0) == (
                True, None)
            time.sleep(3.0)
        finally:
            link.close()
    recs = read_log(log)
    sp = events(recs, "setpoint", "cf2")
    assert len(sp) >= 4 and all(not s["accepted"] and s["reason"] == "vehicle is landed"
                                for s in sp)
    (plan,) = events(recs, "plan", "cf1")
    # Takeoff.height is a float32 on the wire
    assert plan["kind"] == "takeoff" and plan["duration"] == 2.0
    assert plan["to"] == [0.5, 0.2, float(np.float32(0.6))]
    # the trajectory starts when the emulator plans it (its clock: plan["t"]); map the
    # received stamps (emulator seconds) onto it and compare with the polynomial
    z = np.array([(p[7], p[2]) for _, p in poses["cf1"]])
    s = (z[:, 0] - plan["t"]) / 2.0
    ref = np.array([0.6 * _poly(v) for v in s])
    during = (s > 0) & (s < 1.5)
    assert during.sum() > 50
    assert np.max(np.abs(z[during, 1] - ref[during])) < 0.03      # tracks within 3 cm
    assert z[-1, 1] == pytest.approx(0.6, abs=0.01)
    xy = np.array([p[:2] for _, p in poses["cf1"]])
    assert np.abs(xy - [0.5, 0.2]).max() < 0.01
    assert max(p[2] for _, p in poses["cf2"]) == 0.0


def test_setpoint_watchdog_levels_out_then_cuts_the_motors_and_the_vehicle_falls(
        router, tmp_path):
    with cf_emulator(router, "cf1,cf2", tmp_path) as log:
        link, poses, T = _client(router)
        try:
            tk, pubs = _airborne(link, T, 1.5)
            for _ in range(20):
                for p in pubs:
                    p.put(T.encode_velocity_world((0.2, 0.0, 0.0), 0.0, time.time()))
                time.sleep(0.05)
            # cf2: land, then notify_setpoints_stop (the handover); cf1: silence
            assert link.client("/cf2/land", T.LAND).call(height=0.0, duration=1.5)[0]
            assert link.client("/cf2/notify_setpoints_stop", T.NOTIFY).call(
                remain_valid_millisecs=100)[0]
            recs = wait_for(log, lambda r: len(events(r, "ground")) >= 2, timeout=15)
            # a takeoff after the crash is refused: the supervisor is locked
            assert tk[0].call(height=0.5, duration=1.5)[0]
            time.sleep(0.3)
        finally:
            link.close()
    recs = read_log(log)
    last_sp = events(recs, "setpoint", "cf1")[-1]
    last = last_sp["t"]
    (lv,) = events(recs, "wdt_level_out", "cf1")
    (off,) = events(recs, "wdt_motors_off", "cf1")
    (gnd,) = events(recs, "ground", "cf1")
    # on the emulator's physics clock (steps of at most 20 ms): at the firmware's ages ...
    assert 0.5 < lv["age"] <= 0.5 + 0.021 and 2.0 < off["age"] <= 2.0 + 0.021
    assert lv["at"] - last_sp["at"] == pytest.approx(lv["age"], abs=1e-5)
    assert off["at"] - last_sp["at"] == pytest.approx(off["age"], abs=1e-5)
    # ... and on the wall clock, with room for a loaded machine (a line is
    # written a little after its event)
    assert 0.45 < lv["t"] - last < 0.5 + 0.3 and 1.95 < off["t"] - last < 2.0 + 0.3
    # free fall from where the motors stopped: t = sqrt(2 z / g), v = sqrt(2 g z)
    z = off["z"]
    assert 0.4 < z < 0.6
    assert gnd["at"] - off["at"] == pytest.approx(math.sqrt(2 * z / 9.81), abs=0.015)
    assert gnd["speed"] == pytest.approx(math.sqrt(2 * 9.81 * z), rel=0.05)
    assert gnd["mode"] == "falling"
    (ref,) = [r for r in events(recs, "refused", "cf1")]
    assert "locked" in ref["reason"]
    # cf2 landed on its trajectory: no watchdog, a soft touch-down (on the trajectory,
    # or from the few millimetres it lags when the motors stop at its end)
    assert events(recs, "wdt_level_out", "cf2") == []
    (g2,) = events(recs, "ground", "cf2")
    assert g2["mode"] in ("hl", "drop") and g2["speed"] < 0.5
    assert recs[-1]["ev"] == "end" and recs[-1]["modes"] == ["locked", "landed"]


def _yaw_of(p):
    qw, qx, qy, qz = p[3:7]
    return math.atan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))


def test_a_setpoint_after_land_cancels_the_landing_the_reversed_order_drops_the_vehicle(
        router, tmp_path):
    """crazyflie-firmware commander.c: a streamed set-point (CRTP priority, above
    the high-level commander's) stops the high-level planner, so the landing
    planned by a ``land`` that overtook the last set-point is gone; the
    notification then hands control to an idle planner, whose null set-point
    stops the motors: the vehicle falls. Crazyswarm2's order (set-points,
    notify, land) lands it. Truth: free fall from where the motors stopped."""
    with cf_emulator(router, "cf1,cf2", tmp_path) as log:
        link, poses, T = _client(router)
        try:
            time.sleep(0.5)
            for nm in ("cf1", "cf2"):
                assert link.client(f"/{nm}/takeoff", T.TAKEOFF).call(
                    height=0.5, duration=1.5)[0]
            time.sleep(2.0)
            pubs = {nm: link.publisher(f"/{nm}/cmd_full_state", T.FULL_STATE)
                    for nm in ("cf1", "cf2")}
            time.sleep(0.3)
            here = {nm: poses[nm][-1][1][:3] for nm in ("cf1", "cf2")}
            for _ in range(30):                 # hover where they are; cf2 turns to 0.5 rad
                for nm, pub in pubs.items():
                    pub.put(T.encode_full_state(here[nm], (0, 0, 0), (0, 0, 0),
                                                0.5 if nm == "cf2" else 0.0, time.time()))
                time.sleep(0.05)
            # cf1: land, then one more set-point, then the notification (reordered)
            land1 = link.client("/cf1/land", T.LAND)
            assert land1.call(height=0.03, duration=1.5)[0]
            pubs["cf1"].put(T.encode_full_state(here["cf1"], (0, 0, 0), (0, 0, 0), 0.0,
                                                time.time()))
            time.sleep(0.05)
            assert link.client("/cf1/notify_setpoints_stop", T.NOTIFY).call(
                remain_valid_millisecs=100)[0]
            # cf2: Crazyswarm2's order
            assert link.client("/cf2/notify_setpoints_stop", T.NOTIFY).call(
                remain_valid_millisecs=100)[0]
            assert link.client("/cf2/land", T.LAND).call(height=0.03, duration=1.5)[0]
            recs = wait_for(log, lambda r: len(events(r, "ground")) >= 2, timeout=15)
        finally:
            link.close()
    # cf2 turned to the full-state set-point's yaw (crtp_commander_generic.c: the
    # attitude quaternion in modeAbs) and kept it through its landing
    assert _yaw_of(poses["cf2"][-1][1]) == pytest.approx(0.5, abs=0.03)
    (cancel,) = events(recs, "landing_cancelled", "cf1")
    notify = [e for e in events(recs, "service", "cf1")
              if e["service"] == "notify_setpoints_stop"][0]
    assert cancel["at"] < notify["at"]
    (g1,) = events(recs, "ground", "cf1")
    z = here["cf1"][2]
    assert g1["mode"] == "hl" and 0.45 < z < 0.55
    # motors stopped by the idle planner's null set-point at the notification:
    # a free fall from z, t = sqrt(2 z / g), v = sqrt(2 g z)
    assert g1["at"] - notify["at"] == pytest.approx(math.sqrt(2 * z / 9.81), abs=0.03)
    assert g1["speed"] == pytest.approx(math.sqrt(2 * 9.81 * z), rel=0.05)
    (g2,) = events(recs, "ground", "cf2")
    assert g2["mode"] in ("hl", "drop") and g2["speed"] < SOFT_TOUCHDOWN
    assert events(recs, "landing_cancelled", "cf2") == []


def test_a_platform_that_needs_arming_flies_only_once_armed_and_disarms_after_landing(
        router, tmp_path):
    """crazyflie-firmware: a CONFIG_MOTORS_REQUIRE_ARMING platform (the
    Crazyflie 2.1 Brushless, cf21bl_defconfig) reports no auto-arm bit; until an
    arming request it cannot fly and the high-level commander is blocked
    (stabilizer.c); the flying bit stays 2 s after the motors stop
    (IS_FLYING_HYSTERESIS_THRESHOLD) and the landing timeout (3 s) then
    disarms it; a disarm in flight stops the motors. The status bits are those
    of supervisor.c's updateLogData."""
    from avblocks.interfaces.crazyflie import _types as T
    with cf_emulator(router, "cf1,cf2", tmp_path, "--arming", "required") as log:
        link, poses, _ = _client(router)
        bits = {"cf1": [], "cf2": []}

        def on_status(nm):
            def cb(data, now):
                bits[nm].append((time.monotonic(), T.deserialize(data, T.STATUS)
                                 .supervisor_info))
            return cb
        for nm in bits:
            link.subscribe(f"/{nm}/status", T.STATUS, on_status(nm))
        try:
            time.sleep(1.2)
            assert bits["cf1"][-1][1] == 1              # can be armed; nothing else
            tk = {nm: link.client(f"/{nm}/takeoff", T.TAKEOFF) for nm in bits}
            assert tk["cf1"].call(height=0.4, duration=1.0)[0]      # answered, ignored
            time.sleep(0.3)
            for nm in bits:
                assert link.client(f"/{nm}/arm", T.ARM).call(arm=True)[0]
            time.sleep(0.7)
            assert bits["cf1"][-1][1] == 2 | 8          # armed, can fly
            for nm in bits:
                assert tk[nm].call(height=0.4, duration=1.0)[0]
            time.sleep(1.5)
            assert bits["cf1"][-1][1] == 2 | 8 | 16     # ... and flying
            # cf2 disarmed in the air: its motors stop
            assert link.client("/cf2/arm", T.ARM).call(arm=False)[0]
            # cf1 landed by the broadcast service (crazyflie_server.cpp /all/land)
            assert link.client("/all/land", T.LAND).call(height=0.03, duration=1.0)[0]
            recs = wait_for(log, lambda r: len(events(r, "disarmed", "cf1")) == 1,
                            timeout=15)
            time.sleep(0.6)
        finally:
            link.close()
    refused = [e for e in events(recs, "refused", "cf1") if e["service"] == "takeoff"]
    assert len(refused) == 1 and "not armed" in refused[0]["reason"]
    (plan,) = [e for e in events(recs, "plan", "cf1") if e["kind"] == "takeoff"]
    assert plan["t"] > [e for e in events(recs, "armed", "cf1")][0]["t"]
    (d2,) = events(recs, "disarmed", "cf2")
    (g2,) = events(recs, "ground", "cf2")
    assert d2["reason"] == "disarm request" and g2["mode"] == "drop"
    assert g2["speed"] == pytest.approx(math.sqrt(2 * 9.81 * 0.4), rel=0.1)
    (done,) = events(recs, "land_done", "cf1")
    (d1,) = events(recs, "disarmed", "cf1")
    assert d1["reason"].startswith("landing timeout")
    assert d1["t"] - done["t"] == pytest.approx(2.0 + 3.0, abs=0.1)
    # the flying bit: set until 2 s after the landing ended, then clear
    fly = [(t, b & 16) for t, b in bits["cf1"]]
    t_done = done["wall"] - time.time() + time.monotonic()
    assert all(f for t, f in fly if t_done + 0.1 < t < t_done + 1.9)
    assert not any(f for t, f in fly if t > t_done + 2.1)
    assert bits["cf1"][-1][1] == 1                      # disarmed: can be armed again


def test_by_default_the_vehicles_stand_on_drone_formations_start_line(router, tmp_path):
    """``avblocks crazyflies emulate --names cf1,cf2,cf3`` without
    ``--position0`` sets its vehicles down where ``avblocks run
    drone_formation --set agents=3`` starts them (truth: the scenario's own
    ``start_positions``, on the floor), so the start-slot pre-flight takes
    them as they are."""
    from avblocks.scenarios.drone_formation import start_positions
    with cf_emulator(router, "cf1,cf2,cf3", tmp_path) as log:
        (start,) = events(read_log(log), "start")
    np.testing.assert_array_equal(start["position"], start_positions(3, 0.0))


def _pid_of(log):
    """The emulator process writing ``log`` (its command line names it)."""
    from pathlib import Path
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                if str(log).encode() in (d / "cmdline").read_bytes().split(b"\0"):
                    return int(d.name)
            except OSError:
                continue
    raise AssertionError(f"no process writes {log}")


def test_a_pause_of_the_emulator_itself_is_not_set_point_silence(router, tmp_path):
    """The firmware's clock never stops. When the emulator process is not
    running (a loaded host; here SIGSTOP for 0.8 s) while the commander
    streams on, the set-points sent meanwhile wait in its socket: once it
    runs again the watchdog must not count the pause as their age. The
    commander's own silence of the same length (cf2 after the pause) still
    levels its vehicle out at 0.5 s."""
    import os
    import signal
    with cf_emulator(router, "cf1,cf2", tmp_path) as log:
        pid = _pid_of(log)
        link, poses, T = _client(router)
        try:
            _, pubs = _airborne(link, T, 1.0)

            def stream(seconds, which):
                t_end = time.monotonic() + seconds
                while time.monotonic() < t_end:
                    for k in which:
                        pubs[k].put(T.encode_velocity_world((0.0, 0.0, 0.0), 0.0,
                                                            time.time()))
                    time.sleep(0.02)
            stream(0.5, (0, 1))
            os.kill(pid, signal.SIGSTOP)
            try:
                stream(0.8, (0, 1))             # both stream on, unread
            finally:
                os.kill(pid, signal.SIGCONT)
            # then cf2's commander falls silent (the backlog read after the pause
            # can take a few tenths of a second on a loaded machine)
            stream(1.8, (0,))
        finally:
            link.close()
    recs = read_log(log)
    # the SIGSTOP is the longest pause (a loaded machine may add short ones)
    pauses = events(recs, "emulator_paused")
    assert 0.75 < max(p["s"] for p in pauses) < 1.5
    # each pause counts its gap less one tick
    assert recs[-1]["ev"] == "end"
    assert 0.7 < recs[-1]["paused_s"] < sum(p["s"] for p in pauses) + 1e-6
    assert events(recs, "wdt_level_out", "cf1") == []
    (lv,) = events(recs, "wdt_level_out", "cf2")
    assert 0.5 < lv["age"] <= 0.5 + 0.021
    last = [s for s in events(recs, "setpoint", "cf2") if s["accepted"]][-1]
    # its age: the physics time since its last set-point less the emulator's
    # pauses in between (on a loaded machine Zenoh may drop what was sent to the
    # stopped process, so that last set-point can precede the SIGSTOP)
    between = lv["at"] - last["at"]
    assert lv["age"] - 1e-5 <= between <= lv["age"] + recs[-1]["paused_s"] + 1e-5
