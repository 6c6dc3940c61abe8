"""interfaces.mavlink.Drones on a network anyone can reach, and flown by a
careless pilot: what an attack pass on issue 43's commanders found (each
test failed before its fix). Real parts only: the emulator as a subprocess
over UDP on loopback, the hostile party and a second ground station as
plain sockets of the test speaking pymavlink's own encoder, what reached the
vehicle decoded from the emulator's raw log by pymavlink's parser.

* a peer on another address floods spoofed positions, heartbeats and
  acknowledgements from ever new source ports: nothing of it is read, the
  commander sends nothing to it and streams its 20 set-points a second on
  (before: it flew on the spoofed position and sent each set-point to every
  source port, 20 -> 2 a second);
* a second commander on the same port is refused (before: it bound the
  port too, took the telemetry, and the first landed its vehicles as silent);
* a vehicle sending NaN positions and a flood of status texts: refused in
  pre-flight as sending no pose, the log bounded (before: a ValueError deep
  in scipy, and one log line per text);
* a diagram that hangs: landed by the watchdog and the run ends with the
  reason (before: it ran on to the end and said "complete");
* a ground station that switches a vehicle to LAND in flight: the run ends
  and every vehicle lands (before: the commander flew on without it);
* a vehicle already in the air, a takeoff through the geofence's ceiling:
  refused in pre-flight (before: taken off from the air, above the fence);
* the link lost in the takeoff: ended at once (before: after the 30 s
  takeoff timeout, naming stale heights); at the end of the run: reported
  (before: "complete").
"""

from __future__ import annotations

import json
import os
import signal
import socket
import threading
import time

import numpy as np
import pytest

import avblocks as av
from avblocks.core.block import Block
from avblocks.core.errors import SimulationWarning
from avblocks.interfaces.flight import FailsafeError, FlightError, PreflightError
from avblocks.interfaces.mavlink import Drones

from ._mavlink import (
    CMD_ARM,
    CMD_LAND,
    CMD_SET_MODE,
    emulator,
    free_base_port,
    need_pymavlink,
    received,
    wait_landed,
)


class _Hook(Block):
    """Calls ``hook(t)`` at every major step (a side-effect block)."""

    side_effects = True

    def __init__(self, hook):
        super().__init__()
        self.hook = hook

    def output(self, t, x, u, xp):
        return {}

    def on_major_step(self, t, x, u, y):
        self.hook(t)


def _hover(drones, t_final, hook=lambda t: None):
    d = av.Diagram()
    c = d.add(av.blocks.Constant(np.zeros((drones.n, 3))), name="c")
    f = d.add(drones, name="fleet")
    d.connect(c.y, f.velocity)
    d.add(_Hook(hook), name="hook")
    return av.simulate(d, t_final=t_final, dt=0.05, realtime=1.0, progress=False,
                       log=["fleet.position"])


def _encoder(sock, dest, sysid=1, comp=1):
    """pymavlink's MAVLink 2 encoder writing datagrams from ``sock`` to ``dest``."""
    from pymavlink.dialects.v20 import common

    class W:
        def write(self, b):
            try:
                sock.sendto(bytes(b), dest)
            except OSError:
                pass
    return common.MAVLink(W(), srcSystem=sysid, srcComponent=comp)


def _flight_log(path):
    return [json.loads(s) for s in open(path).read().splitlines()]


def test_a_hostile_peer_can_neither_feed_positions_nor_take_the_setpoints(tmp_path):
    need_pymavlink()
    flight = tmp_path / "flight.jsonl"
    stop, socks, sent, window = threading.Event(), [], [0], []

    def flood(dest):
        window.append(time.time())
        while not stop.is_set() and len(socks) < 60:
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)    # a new source port
            s.setblocking(False)
            socks.append(s)
            m = _encoder(s, dest)          # in the vehicle's name: system 1, autopilot
            for _ in range(40):
                m.heartbeat_send(2, 12, 0, 0, 3)                     # "disarmed"
                m.local_position_ned_send(0, 10.0, 10.0, -5.0, 0, 0, 0)
                m.command_ack_send(CMD_LAND, 0, 0, 0, 255, 190)
                sent[0] += 3
            time.sleep(0.02)
        window.append(time.time())

    with emulator(tmp_path, 1, pose0=[[0.0, 0.0, 0.0]]) as (log, spec):
        port = int(spec.rstrip("+").rsplit(":", 1)[1])
        drones = Drones(spec, n=1, takeoff_height=1.0, log=str(flight))
        th = threading.Thread(target=flood, args=(("127.0.0.1", port),), daemon=True)

        def hook(t):
            if t >= 0.5 and not th.is_alive() and not window:
                th.start()
        try:
            res = _hover(drones, 4.0, hook)
        finally:
            stop.set()
            th.join(10)
        landed = wait_landed(log, 1)
    assert landed and sent[0] > 1000 and len(window) == 2
    # the spoofed position (ENU (10, 10, 5)) never reached the diagram: it
    # hovered 1 m above its start
    p = res["fleet.position"][:, 0]
    assert np.abs(p[:, :2]).max() < 0.3 and np.abs(p[-10:, 2] - 1.0).max() < 0.2, p[-1]
    # nothing was sent to the hostile source ports
    got = 0
    for s in socks:
        try:
            got += len(s.recv(65535))
        except BlockingIOError:
            pass
        s.close()
    assert got == 0
    # the set-points reached the vehicle at the configured 20 a second all along
    t_sp = [r["wall"] for r, m in received(log, 1, "SET_POSITION_TARGET_LOCAL_NED")
            if m.type_mask == 1479]
    t0, t1 = window
    rate = sum(t0 <= t <= t1 for t in t_sp) / (t1 - t0)
    assert rate > 17.0, rate
    fl = _flight_log(flight)
    (foreign,) = [r for r in fl if r["ev"] == "foreign_datagrams"]
    assert foreign["count"] > 0.5 * sent[0]
    assert [r for r in fl if r["ev"] == "failsafe"] == []


def test_a_second_commander_on_the_same_port_is_refused_and_the_first_flies_on(tmp_path):
    need_pymavlink()
    with emulator(tmp_path, 1, pose0=[[0.0, 0.0, 0.0]]) as (log, spec):
        first = Drones(spec, n=1, takeoff_height=1.0)
        out = {}

        def fly():
            try:
                out["res"] = _hover(first, 5.0)
            except Exception as e:  # noqa: BLE001 - looked at below
                out["error"] = e
        th = threading.Thread(target=fly, daemon=True)
        th.start()
        t_end = time.monotonic() + 40
        while first.phase != "mission" and time.monotonic() < t_end and th.is_alive():
            time.sleep(0.05)
        assert first.phase == "mission", out
        second = Drones(spec, n=1, takeoff_height=1.0, wait=3.0)
        port = spec.rstrip("+")
        with pytest.raises(PreflightError, match=rf"uav1: cannot open the connection "
                                                 rf"'{port}' \(Address already in use\)"):
            _hover(second, 2.0)
        th.join(60)
        assert wait_landed(log, 1)
    assert "error" not in out, out.get("error")
    assert first.phase == "landed"
    # one commander's commands reached the vehicle: one OFFBOARD, one ARM
    assert len([m for _, m in received(log, 1, "COMMAND_LONG")
                if m.command in (CMD_SET_MODE, CMD_ARM) and m.param1 == 1]) == 2


def test_malformed_numbers_and_a_flood_of_texts_from_a_vehicle(tmp_path):
    """A vehicle (a broken one, or someone in its name from its own address)
    sends NaN positions, a zero quaternion and 5,000 status texts a second."""
    need_pymavlink()
    port = free_base_port(1)
    flight = tmp_path / "flight.jsonl"
    stop = threading.Event()
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))

    def vehicle():
        m = _encoder(s, ("127.0.0.1", port))
        while not stop.is_set():
            m.heartbeat_send(2, 12, 0, 0, 3)
            m.extended_sys_state_send(0, 1)
            m.local_position_ned_send(0, float("nan"), 0.0, 0.0, 0, 0, 0)
            m.attitude_quaternion_send(0, 0.0, 0.0, 0.0, 0.0, 0, 0, 0)
            for _ in range(100):
                m.statustext_send(6, b"flooding")
            time.sleep(0.02)
    th = threading.Thread(target=vehicle, daemon=True)
    th.start()
    t0 = time.monotonic()
    try:
        drones = Drones(f"udpin:127.0.0.1:{port}", n=1, wait=2.0, ack_timeout=0.2,
                        retries=1, retry_budget=0.5, slots=[[0.0, 0.0, 0.0]],
                        log=str(flight))
        with pytest.raises(PreflightError) as e:
            _hover(drones, 1.0)
    finally:
        stop.set()
        th.join(5)
        s.close()
    seconds = time.monotonic() - t0
    assert "uav1: reports no pose" in str(e.value)
    fl = _flight_log(flight)
    texts = [r for r in fl if r["ev"] == "statustext"]
    # at most 10 texts a second are logged, the rest counted
    assert 5 <= len(texts) <= 10 * (seconds + 1), len(texts)
    assert any(r.get("suppressed_before") for r in texts) or [
        r for r in fl if r["ev"] == "suppressed"]
    (bad,) = [r for r in fl if r["ev"] == "malformed"]
    assert bad["vehicle"] == "uav1" and bad["count"] >= 10


def test_a_diagram_that_hangs_is_landed_and_the_run_ends_with_the_reason(tmp_path):
    need_pymavlink()
    done = []

    def hang(t):
        if t >= 1.0 and not done:
            done.append(t)
            time.sleep(1.6)                 # over stall_timeout (1 s)
    with emulator(tmp_path, 1, pose0=[[0.0, 0.0, 0.0]]) as (log, spec):
        drones = Drones(spec, n=1, takeoff_height=1.0)
        with pytest.raises(FailsafeError) as e:
            _hover(drones, 4.0, hang)
        landed = wait_landed(log, 1)
    assert e.value.reason == "stall" and e.value.vehicles == ["uav1"]
    assert "no command step for" in str(e.value)
    assert sorted(landed) == [1]
    assert [m for _, m in received(log, 1, "COMMAND_LONG") if m.command == CMD_LAND]
    # the run ended at the next step after the hang, not at t_final
    assert e.value.results["fleet.position"].shape[0] < 35


def test_a_vehicle_switched_out_of_offboard_ends_the_run_and_every_vehicle_lands(tmp_path):
    """A second ground station (system 254) puts uav1 in PX4's LAND mode in
    flight, as a pilot pressing Land in QGroundControl does."""
    need_pymavlink()
    keep, sent = {}, []
    gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)

    def land_one(t):
        if t >= 1.0 and not sent:
            m = _encoder(gcs, ("127.0.0.1", keep["vehicle_port"]), sysid=254, comp=190)
            m.command_long_send(1, 1, CMD_SET_MODE, 0, 1, 4, 6, 0, 0, 0, 0)  # AUTO.LAND
            sent.append(t)
    with emulator(tmp_path, 2, keep=keep) as (log, spec):
        drones = Drones(spec, n=2, takeoff_height=1.0)
        with pytest.raises(FailsafeError) as e:
            _hover(drones, 6.0, land_one)
        landed = wait_landed(log, 2)
    gcs.close()
    assert e.value.reason == "control" and e.value.vehicles == ["uav1"]
    assert "uav1 left OFFBOARD for AUTO.LAND" in str(e.value)
    assert sorted(landed) == [1, 2]
    assert [m for _, m in received(log, 2, "COMMAND_LONG") if m.command == CMD_LAND]
    assert e.value.results["fleet.position"].shape[0] < 100


def test_preflight_refuses_a_vehicle_already_in_the_air(tmp_path):
    """Another ground station (system 250) armed it and took off (PX4's
    NAV_TAKEOFF, to MIS_TAKEOFF_ALT 2.5 m), then left: a commander must not
    take it over in the air."""
    need_pymavlink()
    from pymavlink import mavutil
    with emulator(tmp_path, 1, pose0=[[0.0, 0.0, 0.0]]) as (log, spec):
        port = spec.rstrip("+")
        other = mavutil.mavlink_connection(port, source_system=250, source_component=190)
        try:
            assert other.wait_heartbeat(timeout=10)
            other.mav.heartbeat_send(6, 8, 0, 0, 4)
            other.mav.command_long_send(1, 1, CMD_ARM, 0, 1, 0, 0, 0, 0, 0, 0)
            other.mav.command_long_send(1, 1, 22, 0, 0, 0, 0, 0, 0, 0, float("nan"))
            t_end = time.monotonic() + 15
            while time.monotonic() < t_end:
                m = other.recv_match(type="LOCAL_POSITION_NED", blocking=True, timeout=1)
                if m is not None and m.z < -0.5:
                    break
            assert m is not None and m.z < -0.5
        finally:
            other.close()
        drones = Drones(spec, n=1, takeoff_height=1.0, wait=3.0)
        with pytest.raises(PreflightError, match=r"uav1: already off the ground "
                                                 r"\(EXTENDED_SYS_STATE (IN_AIR|TAKEOFF)"):
            _hover(drones, 2.0)
    # the commander (system 255) sent no mode change, arming or takeoff
    mine = [m for _, m in received(log, 1, "COMMAND_LONG") if m.get_srcSystem() == 255]
    assert {m.command for m in mine} <= {511}


def test_a_takeoff_through_the_geofence_ceiling_is_refused(tmp_path):
    need_pymavlink()
    with emulator(tmp_path, 1, pose0=[[0.0, 0.0, 0.0]]) as (log, spec):
        drones = Drones(spec, n=1, takeoff_height=1.5, geofence=(-3, 3, -3, 3, 0, 1.0),
                        wait=3.0)
        with pytest.raises(PreflightError, match=r"uav1: takeoff to z=1\.50 m \(1\.5 m above "
                                                 r"where it stands\) would cross the "
                                                 r"geofence's ceiling \(1 m\)"):
            _hover(drones, 2.0)
    assert {m.command for _, m in received(log, 1, "COMMAND_LONG")} <= {511}


def test_a_link_lost_in_the_takeoff_ends_it_at_once(tmp_path):
    """The emulator frozen (SIGSTOP: a radio out of range) as the vehicle
    climbs: the takeoff ends within link_timeout (2 s), naming the silence,
    not at takeoff_timeout (30 s); once it answers again, it lands."""
    need_pymavlink()
    keep, t_stop = {}, []

    def freeze(drones):
        while not any(e["ev"] == "climb" for e in drones.events):
            time.sleep(0.01)
        time.sleep(0.3)
        os.kill(keep["process"].pid, signal.SIGSTOP)
        t_stop.append(time.monotonic())
    with emulator(tmp_path, 1, pose0=[[0.0, 0.0, 0.0]], keep=keep) as (log, spec):
        drones = Drones(spec, n=1, takeoff_height=1.0)
        th = threading.Thread(target=freeze, args=(drones,), daemon=True)
        th.start()
        try:
            with pytest.raises(FlightError) as e:
                _hover(drones, 3.0)
            t_err = time.monotonic()
        finally:
            os.kill(keep["process"].pid, signal.SIGCONT)
        landed = wait_landed(log, 1)
    assert "the takeoff failed: nothing heard from ['uav1'] for more than link_timeout 2 s" \
        in str(e.value)
    assert t_err - t_stop[0] < 6.0
    assert sorted(landed) == [1]


def test_a_landing_not_confirmed_at_the_end_of_the_run_is_reported(tmp_path):
    need_pymavlink()
    keep = {}

    def kill_at_land(drones):
        while drones.phase != "land":
            time.sleep(0.01)
        keep["process"].kill()
    with emulator(tmp_path, 1, pose0=[[0.0, 0.0, 0.0]], keep=keep) as (log, spec):
        drones = Drones(spec, n=1, takeoff_height=1.0)
        th = threading.Thread(target=kill_at_land, args=(drones,), daemon=True)
        th.start()
        with pytest.warns(SimulationWarning, match="not confirmed"):
            res = _hover(drones, 1.0)
    (err,) = res.meta["on_stop_errors"]
    assert "FlightError" in err and "the landing at the end of the run was not " \
        "confirmed: uav1 went silent at z=" in err
