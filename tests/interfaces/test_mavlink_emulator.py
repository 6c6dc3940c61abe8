"""The MAVLink emulator's firmware behaviours, driven by a plain pymavlink
client written here (not the Drones block), over real UDP on loopback:
arming checks, OFFBOARD refused without set-points, the offboard-loss
action (hold / rtl / land), the landing descent rate, the battery."""

import threading
import time

import numpy as np
import pytest

from ._mavlink import free_base_port, need_pymavlink


class Client:
    """A minimal ground station: pymavlink only."""

    def __init__(self, port):
        from pymavlink import mavutil
        self.c = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=255,
                                            source_component=190)
        self.c.mav.heartbeat_send(6, 8, 0, 0, 4)
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
        port = free_base_port(1)
        em = Emulator(pose0=[[0.0, 0.0, 0.0]], base_port=port, **kw)
        th = threading.Thread(target=em.run, daemon=True)
        th.start()
        cl = Client(port)
        made.append((em, th, cl))
        t_end = time.monotonic() + 5
        while cl.last("HEARTBEAT") is None and time.monotonic() < t_end:
            time.sleep(0.05)
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
    time.sleep(0.3)
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
    assert cl.command(400, 1) == 2               # ARM: DENIED, battery low
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
