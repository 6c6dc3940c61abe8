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

from ._cf import cf_emulator, events, read_log, wait_for


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
            time.sleep(0.5)
            tk = [link.client(f"/{nm}/takeoff", T.TAKEOFF) for nm in ("cf1", "cf2")]
            assert all(c.call(height=0.5, duration=1.5)[0] for c in tk)
            time.sleep(2.0)
            pubs = [link.publisher(f"/{nm}/cmd_velocity_world", T.VELOCITY_WORLD)
                    for nm in ("cf1", "cf2")]
            time.sleep(0.3)
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
