"""N PX4 or ArduPilot multicopters over MAVLink as one block.

:class:`Drones` is a :class:`~avblocks.interfaces.flight.Fleet` (ports,
phases, limits, fail-safe and log live there); :class:`MavlinkLink` is
the protocol:

* one pymavlink connection per vehicle (``"udpout:127.0.0.1:14540"``,
  ``"udpin:0.0.0.0:14550"``, a serial port...), a receive thread per
  vehicle, and one sender thread that sends a GCS ``HEARTBEAT`` to every
  vehicle at 1 Hz and re-sends the latest set-point at ``stream_rate`` Hz
  (PX4 leaves OFFBOARD when set-points come slower than 2 Hz; the sender
  stops re-sending a set-point older than ``hold`` seconds, so a hung
  commander is caught by the vehicle's own offboard-loss action);
* the autopilot is told from its heartbeat (``MAV_AUTOPILOT_PX4`` or
  ``MAV_AUTOPILOT_ARDUPILOTMEGA``); every command is a ``COMMAND_LONG``
  whose ``COMMAND_ACK`` is awaited (``ack_timeout``, ``retries``); a
  refusal raises :class:`~avblocks.interfaces.flight.FlightError` naming
  the vehicle, the command, the result and the vehicle's last
  ``STATUSTEXT``;
* takeoff: PX4 streams a position set-point at the vehicle's position,
  switches to OFFBOARD (``DO_SET_MODE``), arms and streams the position
  set-point ``takeoff_height`` above; ArduPilot switches to GUIDED, arms
  and sends ``NAV_TAKEOFF``; both wait until every vehicle is within
  0.1 m of its height and climbs slower than 0.15 m/s;
* mission: velocity set-points as ``SET_POSITION_TARGET_LOCAL_NED`` in
  ``MAV_FRAME_LOCAL_NED`` (type mask 1479: velocity and yaw rate 0 used);
* land / fail-safe: ``NAV_LAND`` (or ``NAV_RETURN_TO_LAUNCH``) to every
  vehicle, three times, acknowledgements not awaited;
* telemetry: ``LOCAL_POSITION_NED`` or ``ODOMETRY`` (positions and
  velocities), ``ATTITUDE_QUATERNION`` (attitude), ``SYS_STATUS`` /
  ``BATTERY_STATUS`` (charge), ``HEARTBEAT`` (armed), ``EXTENDED_SYS_STATE``
  (landed), converted to the world frame by :mod:`.frames` only.
"""

from __future__ import annotations

import threading
import time

import numpy as np

from ...core.errors import ParameterError
from ..flight import Fleet, FleetLink, FlightError, TelemetryBuffer
from . import frames
from .emulator import (
    APM_MODES,
    CMD_ARM,
    CMD_DO_SET_MODE,
    CMD_LAND,
    CMD_RTL,
    CMD_TAKEOFF,
    PX4_MODES,
    mavutil,
)

#: SET_POSITION_TARGET_LOCAL_NED type masks (bits set = ignored).
MASK_VELOCITY = 1 | 2 | 4 | 64 | 128 | 256 | 1024          # 1479: vx vy vz, yaw rate
MASK_POSITION = 8 | 16 | 32 | 64 | 128 | 256 | 1024        # 1528: x y z, yaw rate
RESULTS = {0: "ACCEPTED", 1: "TEMPORARILY_REJECTED", 2: "DENIED", 3: "UNSUPPORTED",
           4: "FAILED", 5: "IN_PROGRESS", 6: "CANCELLED"}
COMMANDS = {CMD_ARM: "ARM", CMD_DO_SET_MODE: "DO_SET_MODE", CMD_TAKEOFF: "NAV_TAKEOFF",
            CMD_LAND: "NAV_LAND", CMD_RTL: "NAV_RETURN_TO_LAUNCH"}


class MavlinkLink(FleetLink):
    """The MAVLink side of :class:`Drones` (see the module docstring)."""

    def __init__(self, names, connections, origins, *, stream_rate=20.0, hold=0.5,
                 ack_timeout=1.0, retries=3, source_system=255, source_component=190,
                 record=None):
        self.names, self.conn_strings = names, connections
        self.n = len(names)
        self.origins = origins
        self.telemetry = TelemetryBuffer(self.n)
        self.stream_rate, self.hold = float(stream_rate), float(hold)
        self.ack_timeout, self.retries = float(ack_timeout), int(retries)
        self.src = (source_system, source_component)
        self.record = record or (lambda *a, **k: None)
        self.conns = []
        self.sysid = [0] * self.n
        self.autopilot = [None] * self.n
        self._acks = [dict() for _ in range(self.n)]
        self._ack_cv = threading.Condition()
        self._send_lock = [threading.Lock() for _ in range(self.n)]
        self._sp = [None] * self.n               # (mask, ned xyz, t_monotonic)
        self._streaming = False
        self._hover = False
        self._landing = False
        self._stop = threading.Event()
        self._threads = []

    # -------------------------------------------------------------- plumbing
    def open(self):
        m = mavutil()
        self.m = m
        for s in self.conn_strings:
            self.conns.append(m.mavlink_connection(s, source_system=self.src[0],
                                                   source_component=self.src[1]))
        for i in range(self.n):
            self._heartbeat(i)           # udpout: the vehicle learns where we are
        for i in range(self.n):
            th = threading.Thread(target=self._rx, args=(i,), daemon=True,
                                  name=f"avblocks-mavlink-rx-{self.names[i]}")
            th.start()
            self._threads.append(th)
        th = threading.Thread(target=self._tx, daemon=True, name="avblocks-mavlink-tx")
        th.start()
        self._threads.append(th)

    def _send(self, i, fn, *args, wait=True):
        lock = self._send_lock[i]
        got = lock.acquire(timeout=0.2 if wait else 0.05)
        try:
            getattr(self.conns[i].mav, fn)(*args)
        except Exception:  # noqa: BLE001 - a closing socket
            pass
        finally:
            if got:
                lock.release()

    def _heartbeat(self, i):
        self._send(i, "heartbeat_send", 6, 8, 0, 0, 4)   # GCS, INVALID autopilot, ACTIVE

    def _rx(self, i):
        c = self.conns[i]
        tb = self.telemetry
        while not self._stop.is_set():
            try:
                msg = c.recv_match(blocking=True, timeout=0.1)
            except Exception:  # noqa: BLE001 - socket closed on shutdown
                if self._stop.is_set():
                    return
                time.sleep(0.01)
                continue
            if msg is None:
                continue
            typ = msg.get_type()
            if typ == "BAD_DATA":
                continue
            sid = msg.get_srcSystem()
            if self.sysid[i] == 0 and typ == "HEARTBEAT" and msg.type != 6:
                self.sysid[i] = sid
            if sid != self.sysid[i] and self.sysid[i] != 0:
                continue
            now = time.monotonic()
            tb.heard(i, now)
            if typ == "HEARTBEAT":
                self.autopilot[i] = ("px4" if msg.autopilot == 12 else "ardupilot"
                                     if msg.autopilot == 3 else "other")
                armed = bool(msg.base_mode & 128)
                tb.armed(i, armed, None if armed else True)
            elif typ == "LOCAL_POSITION_NED":
                tb.pose(i, frames.position_to_world([msg.x, msg.y, msg.z], self.origins[i]),
                        frames.ned_to_enu([msg.vx, msg.vy, msg.vz]), now)
            elif typ == "ODOMETRY" and msg.frame_id == 1:         # pose in MAV_FRAME_LOCAL_NED
                q = frames.quat_to_enu(np.asarray(msg.q, float))
                v = np.array([msg.vx, msg.vy, msg.vz])
                if msg.child_frame_id != 1:      # velocity in the body frame (BODY_FRD, 12)
                    v = _rotmat(np.asarray(msg.q, float)) @ v
                tb.pose(i, frames.position_to_world([msg.x, msg.y, msg.z], self.origins[i]),
                        frames.ned_to_enu(v), now)
                tb.attitude(i, q)
            elif typ == "ATTITUDE_QUATERNION":
                tb.attitude(i, frames.quat_to_enu([msg.q1, msg.q2, msg.q3, msg.q4]))
            elif typ == "SYS_STATUS" and msg.battery_remaining >= 0:
                tb.battery(i, msg.battery_remaining / 100.0)
            elif typ == "BATTERY_STATUS" and msg.battery_remaining >= 0:
                tb.battery(i, msg.battery_remaining / 100.0)
            elif typ == "EXTENDED_SYS_STATE" and msg.landed_state:
                tb.armed(i, tb.snapshot().armed[i], msg.landed_state == 1)
            elif typ == "STATUSTEXT":
                text = msg.text if isinstance(msg.text, str) else msg.text.decode(
                    errors="replace")
                tb.status(i, text.rstrip("\x00"))
                self.record("statustext", vehicle=self.names[i], text=text)
            elif typ == "COMMAND_ACK":
                with self._ack_cv:
                    self._acks[i][msg.command] = msg.result
                    self._ack_cv.notify_all()

    def _tx(self):
        period = 1.0 / self.stream_rate
        next_hb = 0.0
        while not self._stop.wait(period):
            now = time.monotonic()
            if now >= next_hb:
                next_hb = now + 1.0
                for i in range(self.n):
                    self._heartbeat(i)
            if self._streaming and not self._landing:
                for i in range(self.n):
                    sp = self._sp[i]
                    if sp is not None and (self._hover or now - sp[2] <= self.hold):
                        self._setpoint(i, sp[0], sp[1])

    def _setpoint(self, i, mask, xyz):
        ms = int(time.monotonic() * 1000) & 0xFFFFFFFF
        pos = xyz if mask == MASK_POSITION else (0.0, 0.0, 0.0)
        vel = xyz if mask == MASK_VELOCITY else (0.0, 0.0, 0.0)
        self._send(i, "set_position_target_local_ned_send", ms, self.sysid[i] or 1, 1,
                   1, mask, *map(float, pos), *map(float, vel), 0.0, 0.0, 0.0, 0.0, 0.0)

    def command(self, i, cmd, *params):
        """COMMAND_LONG to vehicle ``i``; returns when accepted, else raises
        FlightError naming the vehicle, the command and the reason."""
        p = list(params) + [0.0] * (7 - len(params))
        what = COMMANDS.get(cmd, str(cmd))
        for k in range(max(1, self.retries)):
            with self._ack_cv:
                self._acks[i].pop(cmd, None)
            self._send(i, "command_long_send", self.sysid[i] or 1, 1, cmd, k, *p)
            deadline = time.monotonic() + self.ack_timeout
            with self._ack_cv:
                while cmd not in self._acks[i] and time.monotonic() < deadline:
                    self._ack_cv.wait(0.05)
                res = self._acks[i].get(cmd)
            if res == 0:
                self.record("ack", vehicle=self.names[i], command=what, result="ACCEPTED")
                return
            if res is not None and res != 5:
                time.sleep(0.1)             # the STATUSTEXT comes with the ack
                text = self.telemetry.snapshot().status[i]
                self.record("refused", vehicle=self.names[i], command=what,
                            result=RESULTS.get(res, res), text=text)
                raise FlightError(f"{self.names[i]} refused {what}: "
                                  f"{RESULTS.get(res, res)}"
                                  + (f" ('{text}')" if text else ""),
                                  block="Drones", hint="see the vehicle's messages")
        raise FlightError(f"{self.names[i]} did not acknowledge {what} within "
                          f"{self.retries} x {self.ack_timeout:g} s", block="Drones",
                          hint="is the vehicle connected and the connection string right?")

    def set_mode(self, i, name):
        if self.autopilot[i] == "ardupilot":
            self.command(i, CMD_DO_SET_MODE, 1, APM_MODES[name])
        else:
            main, sub = PX4_MODES[name]
            self.command(i, CMD_DO_SET_MODE, 1, main, sub)

    # -------------------------------------------------------------- phases
    def takeoff(self, height, timeout):
        t_hb = time.monotonic() + 3.0          # the autopilot type comes with HEARTBEAT
        while None in self.autopilot and time.monotonic() < t_hb:
            time.sleep(0.02)
        quiet = [nm for nm, a in zip(self.names, self.autopilot) if a is None]
        if quiet:
            raise FlightError(f"no HEARTBEAT from {quiet} (the autopilot type is "
                              "unknown); nothing was armed", block="Drones")
        tm = self.telemetry.snapshot()
        start = tm.position.copy()
        goal = start + [0.0, 0.0, height]
        self._landing = False
        for i in range(self.n):     # PX4: set-points must flow before OFFBOARD
            local = frames.position_to_local(start[i], self.origins[i])
            self._sp[i] = (None if self.autopilot[i] == "ardupilot"
                           else (MASK_POSITION, local, time.monotonic()))
        self._streaming = True
        self._hover = True      # re-send whatever the age while this phase runs
        time.sleep(0.6)         # set-points before OFFBOARD (PX4)
        for i in range(self.n):
            if self.autopilot[i] == "ardupilot":
                self.set_mode(i, "guided")
                self.command(i, CMD_ARM, 1)
                self.command(i, CMD_TAKEOFF, 0, 0, 0, 0, 0, 0, float(height))
            else:
                self.set_mode(i, "offboard")
                self.command(i, CMD_ARM, 1)
                local = frames.position_to_local(goal[i], self.origins[i])
                self._sp[i] = (MASK_POSITION, local, time.monotonic())
            self.record("climb", vehicle=self.names[i], goal=goal[i].tolist())
        deadline = time.monotonic() + timeout
        while True:
            tm = self.telemetry.snapshot()
            err = np.abs(tm.position[:, 2] - goal[:, 2])
            if np.all(err < 0.1) and np.all(np.abs(tm.velocity[:, 2]) < 0.15):
                break           # there and settled
            if time.monotonic() > deadline:
                slow = [f"{nm} at z={z:.2f} m" for nm, z, e in
                        zip(self.names, tm.position[:, 2], err) if not e < 0.1]
                raise FlightError(f"takeoff to {height:g} m not done within {timeout:g} s: "
                                  + ", ".join(slow), block="Drones")
            time.sleep(0.05)
        # hover there until the mission's first velocity set-point (the
        # block's stall watchdog lands the fleet if that never comes)
        for i in range(self.n):
            self._sp[i] = (MASK_VELOCITY, (0.0, 0.0, 0.0), time.monotonic())

    def send_velocity(self, v):
        if self._landing:
            return
        ned = frames.enu_to_ned(np.asarray(v, float))
        now = time.monotonic()
        self._hover = False
        for i in range(self.n):
            self._sp[i] = (MASK_VELOCITY, ned[i], now)
            self._setpoint(i, MASK_VELOCITY, ned[i])

    def land(self, action="land"):
        self._landing = True
        self._streaming = False
        self._hover = False
        cmd = CMD_RTL if action == "rtl" else CMD_LAND
        for k in range(3):
            for i in range(self.n):
                if i < len(self.conns):
                    self._send(i, "command_long_send", self.sysid[i] or 1, 1, cmd, k,
                               0, 0, 0, float("nan"), float("nan"), float("nan"),
                               float("nan"), wait=False)
            if k < 2:
                time.sleep(0.02)

    def close(self):
        self._stop.set()
        for th in self._threads:
            th.join(timeout=1.0)
        for c in self.conns:
            try:
                c.close()
            except Exception:  # noqa: BLE001
                pass


def _rotmat(q):
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def connections_from(spec, n=None):
    """``"udpout:127.0.0.1:14540+"`` with ``n`` -> n strings on consecutive
    ports; ``"a,b,c"`` -> a list; a list as is."""
    if isinstance(spec, str):
        if spec.endswith("+"):
            if n is None:
                raise ParameterError("a connection 'PREFIX:PORT+' needs the number of "
                                     "vehicles", param="connections", found=spec)
            head, port = spec[:-1].rsplit(":", 1)
            return [f"{head}:{int(port) + k}" for k in range(int(n))]
        spec = [s.strip() for s in spec.split(",") if s.strip()]
    return list(spec)


class Drones(Fleet):
    """N PX4 or ArduPilot multicopters over MAVLink, with the ports of
    :func:`~avblocks.vehicles.velocity_controlled_quadrotor`.

    Ports
    -----
    velocity : in, (N, 3) [m/s]
        World-frame (ENU) velocity, sent as NED ``SET_POSITION_TARGET_LOCAL_NED``.
    position : out, (N, 3) [m]; pose : out, (N, 3) [m, m, rad]
    attitude : out, (N, 4)
        From ``LOCAL_POSITION_NED``/``ODOMETRY`` and ``ATTITUDE_QUATERNION``,
        converted to ENU / FLU.
    fresh : out, (N,) bool; age : out, (N,) [s]
        As :class:`~avblocks.interfaces.flight.Fleet`.

    Parameters
    ----------
    connections : list of str, "a,b" or "udpout:127.0.0.1:14540+"
        One pymavlink connection string per vehicle (``+``: consecutive
        ports for ``n`` vehicles).
    names : list of str, optional
        Vehicle names (default ``uav1`` ...).
    n : int, optional
        Number of vehicles, with a ``PORT+`` connection.
    origins : (N, 3), optional
        World (ENU) position of each vehicle's local NED origin [m]
        (default: the world origin).
    stream_rate : float [Hz]
        Set-point re-send rate (PX4 needs more than 2 Hz).
    hold : float [s]
        The sender stops re-sending a set-point older than this.
    ack_timeout : float [s]; retries : int
        Waiting for each ``COMMAND_ACK``.
    **flight
        The shared flight parameters (:class:`~avblocks.interfaces.flight.Fleet`).

    Equations
    ---------
    ``v_ned = (v_y, v_x, -v_z)`` of the shaped world-frame command;
    positions ``p = origin + (y_ned, x_ned, -z_ned)`` (:mod:`.frames`).

    References
    ----------
    MAVLink common message set; PX4 offboard mode (v1.14); ArduPilot
    Copter GUIDED mode commands.

    Examples
    --------
    >>> from avblocks.interfaces.mavlink import Drones
    >>> b = Drones("udpout:127.0.0.1:14540+", n=2)
    >>> b.names, sorted(b.output_ports)
    (['uav1', 'uav2'], ['age', 'attitude', 'fresh', 'pose', 'position'])
    """

    def __init__(self, connections, names=None, *, n=None, origins=None, stream_rate=20.0,
                 hold=0.5, ack_timeout=1.0, retries=3, **flight):
        if names is not None and n is None:
            n = len(names.split(",") if isinstance(names, str) else names)
        conns = connections_from(connections, n)
        if names is None:
            names = [f"uav{k + 1}" for k in range(len(conns))]
        super().__init__(names, **flight)
        if len(conns) != self.n:
            raise ParameterError("give one connection string per vehicle", block="Drones",
                                 param="connections", expected=self.n, found=len(conns))
        self.connections = conns
        o = np.zeros((self.n, 3)) if origins is None else np.asarray(origins, float)
        if o.shape != (self.n, 3) or not np.isfinite(o).all():
            raise ParameterError("origins must be (N, 3) finite world positions",
                                 block="Drones", param="origins", found=np.shape(o))
        self.origins = o
        if not stream_rate > 2.0:
            raise ParameterError("PX4 needs set-points faster than 2 Hz", block="Drones",
                                 param="stream_rate", expected="> 2", found=stream_rate)
        self.stream_rate, self.hold = float(stream_rate), float(hold)
        self.ack_timeout, self.retries = float(ack_timeout), int(retries)

    def open_link(self):
        return MavlinkLink(self.names, self.connections, self.origins,
                           stream_rate=self.stream_rate, hold=self.hold,
                           ack_timeout=self.ack_timeout, retries=self.retries,
                           record=self.record)
