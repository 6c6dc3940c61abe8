"""interfaces.mavlink.Drones follows each autopilot's documented contract
(issue 43), against the emulator over real sockets, what went on the wire
decoded by pymavlink's own parser from the emulator's raw log:

* ArduPilot streams nothing until asked: the commander asks with
  SET_MESSAGE_INTERVAL (REQUEST_DATA_STREAM where refused) and preflight
  names a vehicle that does not stream what it needs;
* only the autopilot component's HEARTBEAT counts (a gimbal changes
  nothing: ArduPilot is still put in GUIDED, 4, never mode 6, RTL);
* one set-point sender at exactly the configured rate, on the wire;
* PX4: more than a second of set-points before OFFBOARD;
  TEMPORARILY_REJECTED tried again within a budget, IN_PROGRESS awaited
  without re-sending, a spent budget refused clearly;
* the autopilots' own fail-safe parameters read and a vehicle that would
  keep flying refused, unless overridden on purpose."""

import numpy as np
import pytest

from avblocks.interfaces.flight import FlightError, PreflightError
from avblocks.interfaces.mavlink import Drones

from ._mavlink import (
    CMD_ARM,
    CMD_SET_MODE,
    emulator,
    events,
    need_pymavlink,
    received,
    sent_commands,
    wait_landed,
)
from .test_mavlink_flight import _flight

SET_INTERVAL = 511


def _intervals(log, sid):
    """{message id: interval [us]} the vehicle was asked for (decoded)."""
    return {int(m.param1): m.param2 for m in sent_commands(log, sid, SET_INTERVAL)}


def test_ardupilot_over_tcp_streams_only_when_asked_and_flies(tmp_path):
    """ArduPilot (SRx rates 0) reached over TCP as SITL's SERIAL0 is: the
    commander asks for each message it reads, at its rate, and flies."""
    need_pymavlink()
    with emulator(tmp_path, 2, "--flavor", "ardupilot") as (log, spec):
        assert spec.startswith("tcp:127.0.0.1:") and spec.endswith("+10")
        drones = Drones(spec, n=2, takeoff_height=1.0, telemetry_rate=25.0)
        res = _flight(drones, [[0.5, 0.5, 1.0], [2.5, 0.5, 1.0]], t_final=2.0)
        landed = wait_landed(log, 2)
    assert sorted(landed) == [1, 2]
    for sid in (1, 2):
        iv = _intervals(log, sid)
        # LOCAL_POSITION_NED 32, ATTITUDE_QUATERNION 31 at 25 Hz; EXTENDED_SYS_STATE
        # 245 at 5 Hz; SYS_STATUS 1 at 2 Hz: intervals in microseconds
        assert iv == {32: pytest.approx(40000), 31: pytest.approx(40000),
                      245: pytest.approx(200000), 1: pytest.approx(500000)}
        streams = [e for e in events(log, "interval", sid)]
        assert {e["message"] for e in streams} >= {"LOCAL_POSITION_NED",
                                                   "ATTITUDE_QUATERNION",
                                                   "EXTENDED_SYS_STATE"}
        # the first set-point interval request came before anything moved
        first_iv = min(r["wall"] for r, m in received(log, sid, "COMMAND_LONG")
                       if m.command == SET_INTERVAL)
        first_mode = min(r["wall"] for r, m in received(log, sid, "COMMAND_LONG")
                         if m.command == CMD_SET_MODE)
        assert first_iv < first_mode
    z = res["fleet.position"][:, :, 2]
    assert np.all(np.abs(z[0] - 1.0) < 0.12)          # it took off on what it was sent
    q = res["fleet.attitude"][-1]
    assert np.all(np.abs(q[:, 0]) > 0.99)              # attitude from ATTITUDE_QUATERNION


def test_a_vehicle_refusing_the_telemetry_is_named_with_the_message(tmp_path):
    """uav2 refuses SET_MESSAGE_INTERVAL for ATTITUDE_QUATERNION and
    EXTENDED_SYS_STATE: the commander falls back to REQUEST_DATA_STREAM
    (attitude from ATTITUDE, EXTRA1) and names what still does not come."""
    need_pymavlink()
    with emulator(tmp_path, 2, "--flavor", "ardupilot", "--link", "udp",
                  "--deny-interval", "2:ATTITUDE_QUATERNION,EXTENDED_SYS_STATE") as (log, spec):
        drones = Drones(spec, n=2, wait=4.0)
        with pytest.raises(PreflightError) as e:
            _flight(drones, np.zeros((2, 3)))
    msg = str(e.value)
    assert ("uav2: does not stream EXTENDED_SYS_STATE (landed state; SET_MESSAGE_INTERVAL "
            "DENIED; REQUEST_DATA_STREAM POSITION, EXTRA1, EXTENDED_STATUS sent") in msg
    assert "ATTITUDE_QUATERNION" not in msg            # ATTITUDE came instead
    assert "uav1" not in msg
    # the fallback on the wire: MAV_DATA_STREAM_POSITION 6, EXTRA1 10,
    # EXTENDED_STATUS 2, started (start_stop 1), to uav2 only
    rds = [m for _, m in received(log, 2, "REQUEST_DATA_STREAM")]
    assert {m.req_stream_id for m in rds} == {2, 6, 10}
    assert all(m.start_stop == 1 and m.target_system == 2 for m in rds)
    assert not received(log, 1, "REQUEST_DATA_STREAM")
    assert not sent_commands(log, 2, CMD_ARM)          # nothing was commanded


def test_without_set_message_interval_preflight_names_each_missing_message(tmp_path):
    need_pymavlink()
    with emulator(tmp_path, 1, "--flavor", "ardupilot", "--link", "udp",
                  "--no-interval", "1") as (log, spec):
        drones = Drones(spec, n=1, wait=4.0)
        with pytest.raises(PreflightError,
                           match=r"uav1: does not stream EXTENDED_SYS_STATE \(landed state; "
                                 r"SET_MESSAGE_INTERVAL UNSUPPORTED"):
            _flight(drones, np.zeros((1, 3)))


def test_a_gimbal_heartbeat_changes_nothing(tmp_path):
    """A gimbal (component 154, MAV_AUTOPILOT_INVALID) beats just before the
    ArduPilot autopilot: the vehicle is still ArduPilot, put in GUIDED (4);
    mode 6 (RTL on ArduCopter) is never sent."""
    need_pymavlink()
    with emulator(tmp_path, 2, "--flavor", "ardupilot", "--link", "udp",
                  "--gimbal") as (log, spec):
        drones = Drones(spec, n=2, takeoff_height=1.0)
        _flight(drones, [[0.5, 0.5, 1.0], [2.5, 0.5, 1.0]], t_final=1.5)
        landed = wait_landed(log, 2)
    assert sorted(landed) == [1, 2]
    for sid in (1, 2):
        modes = [(m.param1, m.param2) for m in sent_commands(log, sid, CMD_SET_MODE)]
        assert modes and all(mm == (1, 4) for mm in modes), modes
        assert not [e for e in events(log, "mode", sid) if e["to"] == "rtl"]
    comps = [e for e in drones.events if e["ev"] == "component"]
    assert {(e["component"], e["mav_type"]) for e in comps} == {(154, 26)}
    ap = [e for e in drones.events if e["ev"] == "autopilot"]
    assert [(e["component"], e["autopilot"]) for e in ap] == [(1, 3), (1, 3)]


def test_one_sender_streams_setpoints_at_exactly_the_configured_rate(tmp_path):
    """Each diagram step updates the latest set-point; one thread sends
    it: on the wire, 20 Hz (before: every step plus the re-send thread,
    about 40 Hz for a 20 Hz diagram)."""
    need_pymavlink()
    with emulator(tmp_path, 2, pose0=[[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]]) as (log, spec):
        drones = Drones(spec, n=2, takeoff_height=1.0, stream_rate=20.0)
        _flight(drones, [[0.5, 0.5, 1.0], [2.5, 0.5, 1.0]], t_final=5.0)
        wait_landed(log, 2)
    ph = {e["phase"]: e["wall"] for e in drones.events if e["ev"] == "phase"}
    for sid in (1, 2):
        t = np.array([r["wall"] for r, m in received(log, sid, "SET_POSITION_TARGET_LOCAL_NED")
                      if m.type_mask == 1479 and ph["mission"] + 0.5 < r["wall"]
                      < ph["land"] - 0.1])
        rate = (len(t) - 1) / (t[-1] - t[0])
        assert rate == pytest.approx(20.0, rel=0.05), rate
        # no burst either: no one-second window holds more than 22
        counts = [np.sum((t >= a) & (t < a + 1.0)) for a in t[t < t[-1] - 1.0]]
        assert max(counts) <= 22, max(counts)


def test_px4_offboard_after_more_than_a_second_and_rejections_retried(tmp_path):
    """The emulated PX4 refuses OFFBOARD before a second of set-points and
    TEMPORARILY_REJECTs uav1's first two mode changes: the commander
    streams > 1 s first and tries again within its budget."""
    need_pymavlink()
    with emulator(tmp_path, 2, "--temp-reject", "1@2") as (log, spec):
        drones = Drones(spec, n=2, takeoff_height=1.0)
        _flight(drones, [[0.5, 0.5, 1.0], [2.5, 0.5, 1.0]], t_final=1.0)
        landed = wait_landed(log, 2)
    assert sorted(landed) == [1, 2]
    for sid, n_modes in ((1, 3), (2, 1)):
        sps = [r["wall"] for r, _ in received(log, sid, "SET_POSITION_TARGET_LOCAL_NED")]
        modes = [r["wall"] for r, m in received(log, sid, "COMMAND_LONG")
                 if m.command == CMD_SET_MODE]
        assert modes[0] - sps[0] > 1.0                 # PX4: more than a second first
        assert len(modes) == n_modes
        acks = [e["result"] for e in events(log, "ack", sid) if e["command"] == CMD_SET_MODE]
        assert acks == [1] * (n_modes - 1) + [0]       # TEMPORARILY_REJECTED, then ACCEPTED
        assert np.all(np.diff(modes) >= 0.2)           # tried again, not hammered


def test_in_progress_is_awaited_without_resending(tmp_path):
    need_pymavlink()
    with emulator(tmp_path, 1, "--in-progress", "1@1.5",
                  pose0=[[0.0, 0.0, 0.0]]) as (log, spec):
        drones = Drones(spec, n=1, takeoff_height=1.0, ack_timeout=0.5)
        _flight(drones, [[0.5, 0.5, 1.0]], t_final=1.0)
        landed = wait_landed(log, 1)
    assert sorted(landed) == [1]
    for cmd in (CMD_SET_MODE, CMD_ARM):
        sent = sent_commands(log, 1, cmd)
        acks = [e["result"] for e in events(log, "ack", 1) if e["command"] == cmd]
        assert len(sent) == 1 and acks == [5, 0], (len(sent), acks)   # IN_PROGRESS, ACCEPTED


def test_a_spent_retry_budget_is_refused_clearly_and_nothing_is_armed(tmp_path):
    need_pymavlink()
    with emulator(tmp_path, 1, "--temp-reject", "1@100", pose0=[[0.0, 0.0, 0.0]]) \
            as (log, spec):
        drones = Drones(spec, n=1, retry_budget=1.0)
        with pytest.raises(FlightError,
                           match=r"uav1 refused DO_SET_MODE \(OFFBOARD\): TEMPORARILY_REJECTED "
                                 r"\d+ times in [\d.]+ s \(retry_budget 1 s\) \('Command "
                                 r"temporarily rejected: checks not ready'\)"):
            _flight(drones, np.zeros((1, 3)))
    assert not sent_commands(log, 1, CMD_ARM)
    assert 3 <= len(sent_commands(log, 1, CMD_SET_MODE)) <= 5


@pytest.mark.parametrize("flavor, extra, expect", [
    ("px4", ["--factory-defaults"],
     r"uav1: COM_OBL_RC_ACT = 0 \(Position mode\): when the set-points stop it keeps "
     r"flying"),
    ("px4", ["--param", "COM_OF_LOSS_T=5", "--param", "COM_OBL_RC_ACT=5"],
     r"uav1: COM_OBL_RC_ACT = 5 \(Hold mode\).*uav1: COM_OF_LOSS_T = 5 s: it flies on its "
     r"last set-point that long"),
    ("ardupilot", ["--factory-defaults", "--link", "udp"],
     r"uav1: FS_GCS_ENABLE = 0 \(Disabled\): when the commander stops, GUIDED only stops"),
    ("ardupilot", ["--param", "SYSID_MYGCS=250", "--link", "udp"],
     r"uav1: its GCS failsafe watches system 250's heartbeats"),
])
def test_fail_safe_parameters_that_keep_a_vehicle_flying_are_refused(tmp_path, flavor,
                                                                     extra, expect):
    need_pymavlink()
    with emulator(tmp_path, 1, "--flavor", flavor, *extra,
                  pose0=[[0.0, 0.0, 0.0]]) as (log, spec):
        drones = Drones(spec, n=1, wait=4.0)
        with pytest.raises(PreflightError, match=expect):
            _flight(drones, np.zeros((1, 3)))
    asked = {m.param_id for _, m in received(log, 1, "PARAM_REQUEST_READ")}
    want = ({"COM_OF_LOSS_T", "COM_OBL_RC_ACT", "COM_RC_IN_MODE", "NAV_DLL_ACT"}
            if flavor == "px4" else {"FS_GCS_ENABLE", "FS_GCS_TIMEOUT", "GUID_TIMEOUT",
                                     "FS_OPTIONS", "SYSID_MYGCS"})
    assert want <= asked
    assert not sent_commands(log, 1, CMD_ARM) and not sent_commands(log, 1, CMD_SET_MODE)


def test_the_override_flies_a_vehicle_whose_loss_action_keeps_it_flying(tmp_path):
    need_pymavlink()
    with emulator(tmp_path, 1, "--factory-defaults", pose0=[[0.0, 0.0, 0.0]]) as (log, spec):
        drones = Drones(spec, n=1, takeoff_height=1.0, allow_unsafe_failsafe=True)
        _flight(drones, [[0.5, 0.5, 1.0]], t_final=1.0)
        landed = wait_landed(log, 1)
    assert sorted(landed) == [1]
    allowed = [e for e in drones.events if e["ev"] == "unsafe_failsafe_allowed"]
    assert allowed and "COM_OBL_RC_ACT = 0" in allowed[0]["problems"][0]


def test_ardupilot_indoors_flies_once_given_the_ekf_origin(tmp_path):
    """Without GPS, ArduPilot has no local position until SET_GPS_GLOBAL_ORIGIN:
    preflight says so; with ekf_origin the commander sends it first (decoded:
    degrees x 1e7, millimetres) and the vehicle flies."""
    need_pymavlink()
    origin = (47.397742, 8.545594, 488.0)
    with emulator(tmp_path, 1, "--flavor", "ardupilot", "--link", "udp", "--indoor",
                  pose0=[[0.0, 0.0, 0.0]]) as (log, spec):
        with pytest.raises(PreflightError, match=r"uav1: reports no pose.*uav1: does not "
                                                 r"stream LOCAL_POSITION_NED \(position"):
            _flight(Drones(spec, n=1, wait=3.0), np.zeros((1, 3)))
        drones = Drones(spec, n=1, takeoff_height=1.0, ekf_origin=origin)
        _flight(drones, [[0.5, 0.5, 1.0]], t_final=1.0)
        landed = wait_landed(log, 1)
    assert sorted(landed) == [1]
    sgo = [m for _, m in received(log, 1, "SET_GPS_GLOBAL_ORIGIN")]
    assert sgo and (sgo[0].latitude, sgo[0].longitude, sgo[0].altitude) == (
        473977420, 85455940, 488000)


def test_a_second_commander_flies_ardupilot_after_the_first_left(tmp_path):
    """Found on ArduCopter SITL: the first commander's end leaves the GCS
    failsafe on (no heartbeat for FS_GCS_TIMEOUT); a new one arming at once
    was refused ("Arm: GCS failsafe on"). It now beats for a second first."""
    need_pymavlink()
    with emulator(tmp_path, 1, "--flavor", "ardupilot", "--link", "udp",
                  "--gcs-timeout", "2", pose0=[[0.0, 0.0, 0.0]]) as (log, spec):
        _flight(Drones(spec, n=1, takeoff_height=1.0), [[0.5, 0.5, 1.0]], t_final=1.0)
        wait_landed(log, 1)
        import time
        time.sleep(3.0)                                # the GCS failsafe comes on
        drones = Drones(spec, n=1, takeoff_height=1.0)
        _flight(drones, [[0.0, 0.0, 1.0]], t_final=1.0)
        landed = wait_landed(log, 1)
    assert [e for e in events(log, "gcs_loss", 1) if e["action"] is None]
    assert sorted(landed) == [1]
    arms = [e["result"] for e in events(log, "ack", 1) if e["command"] == CMD_ARM]
    assert arms == [0, 0], arms                        # both armed at the first try
