"""interfaces.mavlink.Drones against the MAVLink emulator over real UDP on
loopback (no mocks). What the block sent is read back from the emulator's
log of the raw bytes it received, parsed by pymavlink's own parser
(``_mavlink.decode``), and compared with what the diagram computed after a
hand-written ENU -> NED conversion."""

import numpy as np
import pytest

from avblocks.blocks import Function
from avblocks.core.diagram import Diagram
from avblocks.core.frontend import simulate
from avblocks.interfaces.flight import FailsafeError, FlightError, PreflightError
from avblocks.interfaces.mavlink import Drones

from ._mavlink import (
    CMD_ARM,
    CMD_LAND,
    CMD_SET_MODE,
    emulator,
    events,
    need_pymavlink,
    received,
    wait_landed,
)


def _flight(drones, targets, gain=0.5, nan_after=None, t_final=3.0):
    """Fly ``drones`` toward ``targets`` (N, 3) with v = gain (target - p)."""
    d = Diagram("mav")
    fleet = d.add(drones, name="fleet")
    n = drones.n

    def law(t, p):
        v = gain * (np.asarray(targets, float) - p)
        if nan_after is not None and t >= nan_after:
            v = v.copy()
            v[-1, 0] = np.nan
        return v
    ctl = d.add(Function(law, inputs={"p": (n, 3)}, outputs={"v": (n, 3)}), name="ctl")
    d.connect(fleet.position, ctl.p)
    d.connect(ctl.v, fleet.velocity)
    return simulate(d, t_final=t_final, dt=0.05, realtime=1.0, progress=False,
                    log=["fleet.position", "fleet.pose", "fleet.attitude", "ctl.v"])


def _dedupe(rows):
    out = []
    for r in rows:
        if not out or not np.array_equal(out[-1], r):
            out.append(r)
    return out


def test_setpoints_decoded_independently_equal_the_diagram_after_ned(tmp_path):
    need_pymavlink()
    pose0 = [[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]]
    targets = np.array([[1.0, 1.0, 1.5], [2.5, -1.0, 0.8]])
    with emulator(tmp_path, 2, "--origin", "start", pose0=pose0) as (log, spec):
        drones = Drones(spec, n=2, origins=pose0,
                        takeoff_height=1.0, speed_max=2.0)
        res = _flight(drones, targets)
        landed = wait_landed(log, 2)
    assert sorted(landed) == [1, 2]
    cmds = np.asarray(res["ctl.v"], np.float32)          # (T, 2, 3), ENU
    assert np.abs(cmds).max() > 0.1
    for i in range(2):
        sps = [m for _, m in received(log, i + 1, "SET_POSITION_TARGET_LOCAL_NED")]
        assert all(m.coordinate_frame == 1 and m.target_system == i + 1 for m in sps)
        vel = [m for m in sps if m.type_mask == 1479]
        assert len(vel) > 40
        got = np.array([[m.vx, m.vy, m.vz] for m in vel], np.float32)
        # hand-written ENU -> NED: north = y, east = x, down = -z
        want = np.stack([cmds[:, i, 1], cmds[:, i, 0], -cmds[:, i, 2]], axis=-1)
        got_seq = _dedupe([g for g in got if np.any(g != 0)])
        want_seq = _dedupe(list(want))
        # one sender streams the latest command at its own rate: every
        # set-point on the wire is one of the diagram's commands, in order
        # (a command replaced before the sender's next tick is not sent)
        k = 0
        for g in got_seq:
            while k < len(want_seq) and not np.array_equal(g, want_seq[k]):
                k += 1
            assert k < len(want_seq), f"{g} on the wire is not a later diagram command"
        assert len(got_seq) >= 0.6 * len(want_seq), (len(got_seq), len(want_seq))
        # the takeoff set-points: position 1 m above the start, local frame of
        # the vehicle (origin at its start): NED (0, 0, -1)
        pos = [m for m in sps if m.type_mask == 1528]
        assert pos and np.allclose([pos[-1].x, pos[-1].y, pos[-1].z], [0, 0, -1.0])
        # streamed as PX4 requires: from the first set-point to the LAND
        # command, never a gap of 0.5 s (> 2 Hz), on the wire
        t_sp = [r["wall"] for r, _ in received(log, i + 1, "SET_POSITION_TARGET_LOCAL_NED")]
        t_land = min(r["wall"] for r, m in received(log, i + 1, "COMMAND_LONG")
                     if m.command == CMD_LAND)
        gaps = np.diff([t for t in t_sp if t <= t_land] + [t_land])
        assert gaps.max() < 0.5, gaps.max()
        # heartbeats both ways: the block's, as a GCS, about 1 Hz
        hb = [(r["wall"], m) for r, m in received(log, i + 1, "HEARTBEAT")]
        assert all(m.type == 6 for _, m in hb) and len(hb) >= 4
        assert np.median(np.diff([t for t, _ in hb])) == pytest.approx(1.0, abs=0.2)
    # the flown positions came back through LOCAL_POSITION_NED + origins: the
    # vehicles moved toward their targets (world frame, ENU)
    p = res["fleet.position"]
    assert np.all(np.linalg.norm(p[-1] - targets, axis=1)
                  < np.linalg.norm(p[0] - targets, axis=1) - 0.3)


def test_preflight_refusals_name_each_vehicle_and_reason_nothing_sent(tmp_path):
    need_pymavlink()
    pose0 = [[-5.0, 0.0, 0.0], [0.0, 0.0, 0.0], [2.0, 0.0, 0.0]]
    with emulator(tmp_path, 3, "--battery", "[1.0, 0.1, 1.0]", "--no-pose", "3",
                  pose0=pose0) as (log, spec):
        drones = Drones(spec, n=3, wait=2.0,
                        geofence=(-3, 5, -3, 3, -0.5, 3))
        with pytest.raises(PreflightError) as e:
            _flight(drones, np.zeros((3, 3)))
    msg = str(e.value)
    assert "uav1 at (-5.00, 0.00, 0.00) is outside the geofence" in msg
    assert "uav2: battery low (10 % < battery_min 20 %)" in msg
    assert "uav3: reports no pose" in msg
    for sid in (1, 2, 3):
        # nothing was commanded: heartbeats, telemetry requests, parameter reads
        types = {r["type"] for r, _ in received(log, sid)}
        assert types <= {"HEARTBEAT", "COMMAND_LONG", "PARAM_REQUEST_READ"}, types
        assert {m.command for _, m in received(log, sid, "COMMAND_LONG")} <= {511}
    assert any(ev["ev"] == "preflight_refused" for ev in drones.events)


def test_arming_refused_by_the_vehicle_names_it_and_lands_the_others(tmp_path):
    need_pymavlink()
    with emulator(tmp_path, 2, "--battery", "[1.0, 0.15]") as (log, spec):
        drones = Drones(spec, n=2, battery_min=0.1, retry_budget=1.0)
        # PX4 answers a refused arming TEMPORARILY_REJECTED: tried again
        # until the budget is spent, then refused with the vehicle's text
        with pytest.raises(FlightError, match=r"uav2 refused ARM: TEMPORARILY_REJECTED \d+ "
                                              r"times in [\d.]+ s \(retry_budget 1 s\) "
                                              r"\('Arming denied: battery 15% low'\)"):
            _flight(drones, np.zeros((2, 3)))
        landed = wait_landed(log, 1)
    acks = {(r["sysid"], r["command"], r["result"]) for r in events(log, "ack")}
    assert (2, CMD_ARM, 1) in acks and (1, CMD_ARM, 0) in acks
    arms = [r["wall"] for r, m in received(log, 2, "COMMAND_LONG") if m.command == CMD_ARM]
    assert 3 <= len(arms) <= 5 and arms[-1] - arms[0] <= 1.0 + 0.3
    # uav1 was armed and climbing: it got NAV_LAND and landed
    lands = [m for _, m in received(log, 1, "COMMAND_LONG") if m.command == CMD_LAND]
    assert lands and 1 in landed


@pytest.mark.parametrize("fault, reason, who", [("--silent", "silent", ["uav2"]),
                                                ("--stale", "stale", ["uav1"])])
def test_silent_vehicle_or_stale_pose_lands_every_vehicle_and_keeps_the_log(
        tmp_path, fault, reason, who):
    need_pymavlink()
    sysid = 2 if who == ["uav2"] else 1
    with emulator(tmp_path, 2, fault, f"{sysid}@1.0") as (log, spec):
        drones = Drones(spec, n=2, link_timeout=0.8,
                        stale_timeout=0.6, log=str(tmp_path / "flight.jsonl"))
        with pytest.raises(FailsafeError) as e:
            _flight(drones, [[1.0, 1.0, 1.2], [2.0, 1.0, 1.2]], t_final=20.0)
        landed = wait_landed(log, 2)
    assert e.value.reason == reason and e.value.vehicles == who
    assert e.value.results is not None and len(e.value.results.t) > 10
    assert e.value.results.t[-1] < 6.0
    for sid in (1, 2):          # every vehicle got NAV_LAND (decoded independently)
        assert any(m.command == CMD_LAND for _, m in received(log, sid, "COMMAND_LONG"))
    assert sorted(landed) == [1, 2]
    import json
    recs = [json.loads(s) for s in open(tmp_path / "flight.jsonl")]
    fs = [r for r in recs if r["ev"] == "failsafe"]
    assert fs and fs[0]["reason"] == reason and recs[-1]["ev"] == "end"


def test_nan_command_lands_every_vehicle(tmp_path):
    need_pymavlink()
    with emulator(tmp_path, 2) as (log, spec):
        drones = Drones(spec, n=2)
        with pytest.raises(FailsafeError, match=r"NaN or infinite for \['uav2'\]") as e:
            _flight(drones, [[0.0, 1.0, 1.2], [2.0, 1.0, 1.2]], nan_after=1.0, t_final=10)
        landed = wait_landed(log, 2)
    assert e.value.reason == "nan" and sorted(landed) == [1, 2]
    # no set-point with a NaN ever left the block
    for sid in (1, 2):
        for _, m in received(log, sid, "SET_POSITION_TARGET_LOCAL_NED"):
            assert np.isfinite([m.vx, m.vy, m.vz, m.x, m.y, m.z]).all()


def test_ardupilot_guided_takeoff_and_land(tmp_path):
    need_pymavlink()
    with emulator(tmp_path, 2, "--flavor", "ardupilot") as (log, spec):
        drones = Drones(spec, n=2, takeoff_height=1.2)
        res = _flight(drones, [[0.5, 0.5, 1.2], [2.5, 0.5, 1.2]], t_final=2.0)
        landed = wait_landed(log, 2)
    assert sorted(landed) == [1, 2]
    for sid in (1, 2):
        cmds = [m for _, m in received(log, sid, "COMMAND_LONG")]
        modes = [m.param2 for m in cmds if m.command == CMD_SET_MODE]
        assert modes[0] == 4                               # GUIDED (ArduCopter)
        take = [m for m in cmds if m.command == 22]
        assert take and take[0].param7 == pytest.approx(1.2)
        # no set-point before the takeoff ended (ArduPilot climbs on its own)
        sps = received(log, sid, "SET_POSITION_TARGET_LOCAL_NED")
        assert sps and all(m.type_mask == 1479 for _, m in sps)
    assert np.all(np.abs(res["fleet.position"][0, :, 2] - 1.2) < 0.12)


def test_geofence_cut_stops_a_vehicle_at_the_face(tmp_path):
    need_pymavlink()
    with emulator(tmp_path, 1, pose0=[[0.0, 0.0, 0.0]]) as (log, spec):
        drones = Drones(spec, n=1, takeoff_height=1.0,
                        geofence=(-1.0, 1.0, -1.0, 1.0, 0.0, 2.0), lookahead=1.0)
        d = Diagram("fence")
        fleet = d.add(drones, name="fleet")
        c = d.add(Function(lambda t: np.array([[0.8, 0.0, 0.0]]), outputs={"v": (1, 3)}),
                  name="c")
        d.connect(c.v, fleet.velocity)
        res = simulate(d, t_final=6.0, dt=0.05, realtime=1.0, progress=False,
                       log=["fleet.position"])
        wait_landed(log, 1)
    east = np.array([m.vy for _, m in received(log, 1, "SET_POSITION_TARGET_LOCAL_NED")
                     if m.type_mask == 1479])
    x = res["fleet.position"][:, 0, 0]
    # the wanted 0.8 m/s east is cut to (1 - x) / 1 s: never more than the
    # distance left, down to a crawl at the face, and the vehicle stays inside
    assert east.max() <= 0.8 + 1e-6 and east[-5:].max() < 0.15
    assert 0.8 < x[-1] <= 1.0 + 0.05


def test_separation_breach_lands_every_vehicle_with_a_limit_error(tmp_path):
    need_pymavlink()
    from avblocks.interfaces.flight import LimitError
    with emulator(tmp_path, 2, pose0=[[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]]) as (log, spec):
        drones = Drones(spec, n=2, min_separation=0.8)
        with pytest.raises(LimitError, match=r"uav1-uav2 0\.[0-7]\d m apart "
                                             r"\(min_separation 0\.8 m\)") as e:
            _flight(drones, [[1.6, 0.0, 1.0], [0.4, 0.0, 1.0]], gain=0.8, t_final=20)
        landed = wait_landed(log, 2)
    assert e.value.reason == "limit" and e.value.vehicles == ["uav1", "uav2"]
    assert sorted(landed) == [1, 2]


@pytest.mark.parametrize("message", ["local", "odometry"])
def test_positions_and_heading_from_local_position_or_odometry(tmp_path, message):
    """The block's outputs against the emulator's own (ENU) state, logged
    when the LAND command arrives right after the run: positions within
    a few cm, and the heading east of the emulated vehicles is yaw 0."""
    need_pymavlink()
    with emulator(tmp_path, 2, "--pose-message", message,
                  pose0=[[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]]) as (log, spec):
        drones = Drones(spec, n=2, takeoff_height=1.0)
        res = _flight(drones, [[0.5, 1.0, 1.5], [2.5, -1.0, 0.8]], t_final=4.0)
        wait_landed(log, 2)
    for sid in (1, 2):
        truth = [e for e in events(log, "mode", sid) if e["to"] == "land"][0]["pos"]
        np.testing.assert_allclose(res["fleet.position"][-1, sid - 1], truth, atol=0.06)
    q = res["fleet.attitude"][-1]
    assert np.all(np.abs(q[:, 0]) > 0.99)                   # level, facing east
    assert np.all(np.abs(res["fleet.pose"][-1, :, 2]) < 0.05)
