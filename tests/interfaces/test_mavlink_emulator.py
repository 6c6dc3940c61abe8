"""The MAVLink emulator's firmware behaviours, driven by a plain pymavlink
client written here (not the Drones block), over real UDP on loopback,
each against what PX4's or ArduPilot's documentation and sources say
(cited in ``avblocks.interfaces.mavlink.emulator``): arming checks,
OFFBOARD refused without (more than a second of) set-points, the
offboard-loss action (hold / rtl / land), the landing descent rate, the
battery; ArduPilot streaming nothing until asked (SET_MESSAGE_INTERVAL,
REQUEST_DATA_STREAM groups), its mode numbers, its GCS failsafe; the
parameters on the wire (PX4 byte-wise, ArduPilot C-cast, decoded here
with struct); the gimbal's heartbeat; the EKF origin indoors."""

import struct
import threading
import time

import numpy as np
import pytest

from ._mavlink import free_base_port, need_pymavlink


class Client:
    """A minimal ground station: pymavlink only, listening where the
    emulated vehicle sends (PX4 SITL's layout: ``udpin``)."""

    def __init__(self, port):
        from pymavlink import mavutil
        self.c = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255,
                                            source_component=190)
        self.msgs = []
        self.stop = threading.Event()
        self.t = threading.Thread(target=self._rx, daemon=True)
        self.t.start()

    def _rx(self):
        while not self.stop.is_set():
            m = self.c.recv_match(blocking=True, timeout=0.1)
            if m is not None and m.get_type() != "BAD_DATA":
                self.msgs.append((time.monotonic(), m))

    def last(self, mtype):
        for _, m in reversed(self.msgs):
            if m.get_type() == mtype:
                return m
        return None

    def series(self, mtype, since=0.0):
        return [(t, m) for t, m in list(self.msgs) if m.get_type() == mtype and t >= since]

    def command(self, cmd, *p, timeout=2.0):
        p = list(p) + [0.0] * (7 - len(p))
        t0 = time.monotonic()
        self.c.mav.command_long_send(1, 1, cmd, 0, *p)
        while time.monotonic() - t0 < timeout:
            for t, m in reversed(list(self.msgs)):
                if t >= t0 and m.get_type() == "COMMAND_ACK" and m.command == cmd:
                    return m.result
            time.sleep(0.02)
        return None

    def wait(self, mtype, timeout=3.0, since=0.0):
        t_end = time.monotonic() + timeout
        while time.monotonic() < t_end:
            got = self.series(mtype, since)
            if got:
                return got[-1][1]
            time.sleep(0.02)
        return None

    def param(self, name, timeout=2.0):
        """PARAM_VALUE for ``name`` (the message, undecoded)."""
        t0 = time.monotonic()
        self.c.mav.param_request_read_send(1, 1, name.encode(), -1)
        t_end = t0 + timeout
        while time.monotonic() < t_end:
            for _, m in self.series("PARAM_VALUE", t0):
                if m.param_id == name:
                    return m
            time.sleep(0.02)
        return None

    def setpoint_pos(self, x, y, z):
        self.c.mav.set_position_target_local_ned_send(0, 1, 1, 1, 1528, x, y, z,
                                                      0, 0, 0, 0, 0, 0, 0, 0)

    def close(self):
        self.stop.set()
        self.t.join(1)
        self.c.close()


@pytest.fixture
def fleet():
    """An in-process Emulator (its Python API) and a client per test."""
    need_pymavlink()
    from avblocks.interfaces.mavlink import Emulator
    made = []

    def make(**kw):
        port, vport = free_base_port(1), free_base_port(1)
        kw.setdefault("link", "udp")
        cl = Client(port)
        em = Emulator(pose0=[[0.0, 0.0, 0.0]], base_port=port, vehicle_port=vport, **kw)
        th = threading.Thread(target=em.run, daemon=True)
        th.start()
        made.append((em, th, cl))
        t_end = time.monotonic() + 5
        while cl.last("HEARTBEAT") is None and time.monotonic() < t_end:
            time.sleep(0.05)
        cl.c.mav.heartbeat_send(6, 8, 0, 0, 4)
        return em, cl
    yield make
    for em, th, cl in made:
        cl.close()
        em.stop()
        th.join(5)
        em.close()


def _take_off(cl, z_ned=-1.0):
    stop = threading.Event()

    def stream():
        while not stop.is_set():
            cl.setpoint_pos(0.0, 0.0, z_ned)
            time.sleep(0.05)
    th = threading.Thread(target=stream, daemon=True)
    th.start()
    time.sleep(1.2)                              # PX4: more than a second first
    assert cl.command(176, 1, 6) == 0            # OFFBOARD
    assert cl.command(400, 1) == 0               # ARM
    t_end = time.monotonic() + 10
    while time.monotonic() < t_end:
        m = cl.last("LOCAL_POSITION_NED")
        if m is not None and abs(m.z - z_ned) < 0.05 and abs(m.vz) < 0.05:
            break
        time.sleep(0.05)
    return stop


def test_arming_checks_and_offboard_without_setpoints(fleet):
    em, cl = fleet(battery=0.1)
    assert cl.command(176, 1, 6) == 1            # OFFBOARD: TEMPORARILY_REJECTED
    assert cl.command(400, 1) == 1               # ARM: TEMPORARILY_REJECTED, battery low
    texts = [m.text for _, m in cl.series("STATUSTEXT")]
    assert any("battery 10% low" in t for t in texts)
    assert 9 <= cl.last("SYS_STATUS").battery_remaining <= 10
    assert cl.last("BATTERY_STATUS").battery_remaining in (9, 10)
    assert not em.armed[0]


@pytest.mark.parametrize("action", ["hold", "land", "rtl"])
def test_offboard_loss_action(fleet, action):
    em, cl = fleet(offboard_timeout=0.5, offboard_loss_action=action)
    stop = _take_off(cl)
    if action == "rtl":          # fly away first so that returning means something
        stop.set()
        time.sleep(0.1)
        stop = threading.Event()

        def stream():
            while not stop.is_set():
                cl.setpoint_pos(1.0, 1.0, -1.0)
                time.sleep(0.05)
        threading.Thread(target=stream, daemon=True).start()
        time.sleep(3.0)
    t_stop = time.monotonic()
    stop.set()                                     # the set-points stop
    time.sleep(6.0 if action != "rtl" else 9.0)
    modes = [m.custom_mode for t, m in cl.series("HEARTBEAT", t_stop)]
    px4 = {"hold": (4 << 16) | (3 << 24), "land": (4 << 16) | (6 << 24),
           "rtl": (4 << 16) | (5 << 24)}
    assert px4[action] in modes
    pos = cl.last("LOCAL_POSITION_NED")
    if action == "hold":          # hovers where it was
        assert abs(pos.z + 1.0) < 0.1 and em.armed[0]
    elif action == "land":
        assert abs(pos.z) < 0.03 and not em.armed[0]
    else:                          # back over home, then down
        assert np.hypot(pos.x, pos.y) < 0.2 and abs(pos.z) < 0.03 and not em.armed[0]
    loss = [e for e in em.events if e["ev"] == "offboard_loss"]
    assert loss and loss[0]["wall"] - time.time() + time.monotonic() - t_stop \
        == pytest.approx(0.5, abs=0.25)                 # after COM_OF_LOSS_T


def test_land_descends_at_land_speed(fleet):
    em, cl = fleet(land_speed=0.7)
    stop = _take_off(cl, -2.0)
    stop.set()
    t0 = time.monotonic()
    assert cl.command(21) == 0                     # NAV_LAND
    time.sleep(4.0)
    zs = [(t, -m.z) for t, m in cl.series("LOCAL_POSITION_NED", t0)]
    mid = [(t, z) for t, z in zs if 0.4 < z < 1.5]
    slope = np.polyfit([t for t, _ in mid], [z for _, z in mid], 1)[0]
    assert slope == pytest.approx(-0.7, rel=0.1)
    assert zs[-1][1] < 0.03 and not em.armed[0]


def test_ardupilot_gcs_heartbeat_loss_lands(fleet):
    em, cl = fleet(flavor="ardupilot", gcs_timeout=1.0, gcs_loss_action="land")
    stop = threading.Event()

    def beat():
        while not stop.is_set():
            cl.c.mav.heartbeat_send(6, 8, 0, 0, 4)
            time.sleep(0.2)
    threading.Thread(target=beat, daemon=True).start()
    assert cl.command(511, 32, 50_000) == 0      # ArduPilot: ask for LOCAL_POSITION_NED
    assert cl.command(176, 1, 4) == 0            # GUIDED
    assert cl.command(400, 1) == 0               # ARM
    assert cl.command(22, 0, 0, 0, 0, 0, 0, 1.0) == 0      # NAV_TAKEOFF 1 m
    time.sleep(3.0)
    assert abs(cl.last("LOCAL_POSITION_NED").z + 1.0) < 0.1
    t_stop = time.monotonic()
    stop.set()                                   # the GCS goes quiet
    time.sleep(4.5)
    loss = [e for e in em.events if e["ev"] == "gcs_loss"]
    assert loss and loss[0]["wall"] - time.time() + time.monotonic() - t_stop \
        == pytest.approx(1.0, abs=0.35)          # FS_GCS_TIMEOUT after the last beat
    assert 9 in [m.custom_mode for t, m in cl.series("HEARTBEAT", t_stop)]   # LAND
    assert abs(cl.last("LOCAL_POSITION_NED").z) < 0.03 and not em.armed[0]


def test_ardupilot_streams_nothing_until_asked(fleet):
    """Copter's SRx_ rates default to 0 (GCS_MAVLink_Parameters.cpp): only
    HEARTBEAT; SET_MESSAGE_INTERVAL starts one message at its interval;
    REQUEST_DATA_STREAM starts a group (EXTRA1: ATTITUDE, never
    ATTITUDE_QUATERNION); an unknown message is DENIED with a STATUSTEXT."""
    em, cl = fleet(flavor="ardupilot")
    t0 = time.monotonic()
    time.sleep(1.5)
    assert {m.get_type() for t, m in list(cl.msgs) if t >= t0} <= {"HEARTBEAT"}
    assert cl.command(511, 31, 100_000) == 0          # ATTITUDE_QUATERNION every 0.1 s
    t1 = time.monotonic()
    time.sleep(2.0)
    n = len(cl.series("ATTITUDE_QUATERNION", t1 + 0.2))
    assert 15 <= n <= 20, n                            # 10 Hz over 1.8 s
    assert not cl.series("LOCAL_POSITION_NED") and not cl.series("EXTENDED_SYS_STATE")
    cl.c.mav.request_data_stream_send(1, 1, 10, 5, 1)  # EXTRA1 at 5 Hz
    t2 = time.monotonic()
    time.sleep(2.0)
    n = len(cl.series("ATTITUDE", t2 + 0.2))
    assert 7 <= n <= 11, n
    assert not cl.series("LOCAL_POSITION_NED")
    assert cl.command(511, 331, 100_000) == 2          # ODOMETRY: DENIED
    assert any("No ap_message for mavlink id (331)" in m.text
               for _, m in cl.series("STATUSTEXT"))
    assert cl.command(511, 31, -1) == 0                # -1: stop it
    t3 = time.monotonic()
    time.sleep(0.8)
    assert not cl.series("ATTITUDE_QUATERNION", t3 + 0.2)


def test_px4_streams_its_onboard_defaults_and_answers_interval_requests(fleet):
    em, cl = fleet()
    t0 = time.monotonic()
    time.sleep(2.2)
    lp = len(cl.series("LOCAL_POSITION_NED", t0 + 0.2))
    ess = len(cl.series("EXTENDED_SYS_STATE", t0 + 0.2))
    assert lp >= 40 and 8 <= ess <= 12, (lp, ess)      # 30 Hz (the emulator's rate), 5 Hz
    assert cl.command(511, 245, 1_000_000) == 0        # EXTENDED_SYS_STATE at 1 Hz
    t1 = time.monotonic()
    time.sleep(2.2)
    assert 1 <= len(cl.series("EXTENDED_SYS_STATE", t1 + 0.1)) <= 3


def test_ardupilot_mode_numbers_are_copters(fleet):
    """mode.h: 4 GUIDED, 6 RTL, 9 LAND; DO_SET_MODE without the custom-mode
    flag is DENIED, an unknown mode FAILED (_set_mode_common)."""
    em, cl = fleet(flavor="ardupilot")
    assert cl.command(176, 1, 6) == 0
    assert em.mode[0] == "rtl"
    time.sleep(1.2)
    assert cl.last("HEARTBEAT").custom_mode == 6
    assert cl.command(176, 1, 4) == 0 and em.mode[0] == "guided"
    assert cl.command(176, 0, 9) == 2                  # no custom-mode flag: DENIED
    assert cl.command(176, 1, 99) == 4                 # no such mode: FAILED
    assert em.mode[0] == "guided"


def test_px4_offboard_needs_more_than_a_second_of_setpoints(fleet):
    """The offboard page (v1.16): offboard only after more than a second of
    set-points; refused TEMPORARILY_REJECTED before."""
    em, cl = fleet()
    stop = threading.Event()

    def stream():
        while not stop.is_set():
            cl.setpoint_pos(0.0, 0.0, 0.0)
            time.sleep(0.05)
    threading.Thread(target=stream, daemon=True).start()
    try:
        time.sleep(0.6)
        assert cl.command(176, 1, 6) == 1              # 0.6 s: TEMPORARILY_REJECTED
        time.sleep(0.6)
        assert cl.command(176, 1, 6) == 0              # 1.2 s: ACCEPTED
    finally:
        stop.set()


@pytest.mark.parametrize("flavor, name, value, field", [
    ("px4", "COM_OBL_RC_ACT", 4, "bytes"), ("px4", "COM_OF_LOSS_T", 0.5, "float"),
    ("ardupilot", "FS_GCS_ENABLE", 5, "float"), ("ardupilot", "GUID_TIMEOUT", 3.0, "float")])
def test_parameters_on_the_wire(fleet, flavor, name, value, field):
    """PX4 puts an INT32 parameter's bytes into PARAM_VALUE's float;
    ArduPilot casts it (MAVLink parameter protocol, "Parameter Encoding"):
    decoded here with struct, not with avblocks."""
    em, cl = fleet(flavor=flavor)
    m = cl.param(name)
    assert m is not None
    if field == "bytes":
        assert m.param_type == 6                       # MAV_PARAM_TYPE_INT32
        assert struct.unpack("<i", struct.pack("<f", m.param_value))[0] == value
    else:
        assert m.param_value == pytest.approx(value)
    assert cl.param("NO_SUCH_PARAM", timeout=0.8) is None   # unknown: no answer
    # PARAM_SET changes what the firmware does
    if flavor == "px4" and name == "COM_OBL_RC_ACT":
        raw = struct.unpack("<f", struct.pack("<i", 5))[0]
        cl.c.mav.param_set_send(1, 1, name.encode(), raw, 6)
        time.sleep(0.5)
        assert em.params[0][name] == 5


def test_a_gimbal_component_beats_with_an_invalid_autopilot(fleet):
    em, cl = fleet(flavor="ardupilot", gimbal=True)
    time.sleep(2.2)
    hb = [m for _, m in cl.series("HEARTBEAT")]
    gimbal = [m for m in hb if m.get_srcComponent() == 154]
    autopilot = [m for m in hb if m.get_srcComponent() == 1]
    assert gimbal and autopilot
    assert {(m.type, m.autopilot) for m in gimbal} == {(26, 8)}
    assert {(m.type, m.autopilot) for m in autopilot} == {(2, 3)}
    assert {m.get_srcSystem() for m in hb} == {1}


def test_ardupilot_indoors_has_no_local_position_until_the_ekf_origin(fleet):
    """send_local_position needs the EKF origin; SET_GPS_GLOBAL_ORIGIN sets it."""
    em, cl = fleet(flavor="ardupilot", indoor=True)
    assert cl.command(511, 32, 100_000) == 0
    assert cl.command(176, 1, 4) == 4                  # GUIDED: FAILED, no position
    time.sleep(1.0)
    assert not cl.series("LOCAL_POSITION_NED")
    cl.c.mav.set_gps_global_origin_send(1, int(47.3977 * 1e7), int(8.5456 * 1e7), 488000)
    assert cl.wait("LOCAL_POSITION_NED", timeout=2.0) is not None
    assert cl.command(176, 1, 4) == 0


def test_ardupilot_gcs_failsafe_counts_only_sysid_mygcs(fleet):
    """events.cpp: the GCS failsafe looks at the heartbeats of SYSID_MYGCS
    only; a ground station with another system id does not keep it away."""
    em, cl = fleet(flavor="ardupilot", gcs_timeout=1.0, gcs_loss_action="land",
                   params={"SYSID_MYGCS": 250})
    stop = threading.Event()

    def beat():              # heartbeats as system 255, not 250
        while not stop.is_set():
            cl.c.mav.heartbeat_send(6, 8, 0, 0, 4)
            time.sleep(0.2)
    threading.Thread(target=beat, daemon=True).start()
    try:
        assert cl.command(176, 1, 4) == 0
        assert cl.command(400, 1) == 0
        assert cl.command(22, 0, 0, 0, 0, 0, 0, 1.0) == 0
        time.sleep(2.5)
        # never seen system 250: no failsafe, whatever the other GCS does
        assert not [e for e in em.events if e["ev"] == "gcs_loss"]
        assert em.mode[0] in ("takeoff", "guided") and em.armed[0]
    finally:
        stop.set()


def test_ardupilot_refuses_to_arm_while_its_gcs_failsafe_is_on(fleet):
    """Found flying ArduCopter SITL: the GCS failsafe is checked at 3 Hz,
    armed or not (events.cpp, three_hz_loop); after a ground station went
    quiet it is on, and arming is refused ("GCS failsafe on",
    AP_Arming_Copter.cpp) until a check after the next heartbeat clears it."""
    em, cl = fleet(flavor="ardupilot", gcs_timeout=2.0)
    assert cl.command(176, 1, 4) == 0                  # GUIDED; our heartbeat was seen
    time.sleep(2.8)                                    # quiet for > FS_GCS_TIMEOUT
    assert em.gcs_failsafe[0]
    cl.c.mav.heartbeat_send(6, 8, 0, 0, 4)
    assert cl.command(400, 1, timeout=1.0) == 4        # FAILED at once
    assert any("GCS failsafe on" in m.text for _, m in cl.series("STATUSTEXT"))
    time.sleep(0.5)                                    # the next 3 Hz check
    cl.c.mav.heartbeat_send(6, 8, 0, 0, 4)
    assert cl.command(400, 1) == 0 and em.armed[0]
    assert [e for e in em.events if e["ev"] == "gcs_failsafe_cleared"]


def test_by_default_the_vehicles_stand_on_drone_formations_start_line():
    """Without ``pose0`` the emulated vehicles stand where the drone_formation
    scenario starts N agents (truth: the scenario's own ``start_positions``,
    on the floor), so ``avblocks run drone_formation --set agents=N`` finds
    each on its start slot; PX4's vehicle ports are the base port + 40 (SITL:
    14540+i and 14580+i)."""
    need_pymavlink()
    from avblocks.interfaces.mavlink import Emulator
    from avblocks.scenarios.drone_formation import start_positions
    for n in (1, 2, 5):
        for _ in range(20):
            base = free_base_port(n)
            try:
                em = Emulator(n=n, base_port=base)
            except OSError:             # base + 40 ... taken: another base
                continue
            break
        else:
            pytest.fail("no free pair of port ranges")
        try:
            np.testing.assert_array_equal(em.home, start_positions(n, 0.0))
            assert em.ports == [base + i for i in range(n)]
            assert em.vehicle_ports == [base + 40 + i for i in range(n)]
        finally:
            em.close()
    em = Emulator(n=3, base_port=free_base_port(3), vehicle_port=free_base_port(3),
                  spacing=0.5)
    try:
        np.testing.assert_array_equal(em.home[:, 0], [-0.5, 0.0, 0.5])
    finally:
        em.close()
