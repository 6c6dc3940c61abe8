"""N PX4 or ArduPilot multicopters over MAVLink as one block.

:class:`Drones` is a :class:`~avblocks.interfaces.flight.Fleet` (ports,
phases, limits, fail-safe and log live there); :class:`MavlinkLink` is
the protocol, written to each autopilot's documented contract (the
numbers and their sources are in :mod:`.autopilots`):

* **links**: one pymavlink connection per vehicle: PX4 SITL
  ``udpin:127.0.0.1:14540`` (instance i sends to 14540 + i), ArduPilot
  SITL ``tcp:127.0.0.1:5760`` (5760 + 10 i), a telemetry radio
  ``serial:/dev/ttyUSB0:57600``; a receive thread per vehicle and one
  sender thread;
* **who is the vehicle**: only HEARTBEATs from the autopilot component
  (``MAV_COMP_ID_AUTOPILOT1``, autopilot not ``MAV_AUTOPILOT_INVALID``)
  give the system id, the autopilot (PX4 or ArduPilot), the vehicle type
  and the armed state; a gimbal's or a companion computer's heartbeat of
  the same system changes nothing; telemetry, acknowledgements and
  parameters are taken from that component only;
* **telemetry asked for, and checked**: ``MAV_CMD_SET_MESSAGE_INTERVAL``
  for ``LOCAL_POSITION_NED`` and ``ATTITUDE_QUATERNION`` (at
  ``telemetry_rate``), ``EXTENDED_SYS_STATE`` (5 Hz) and ``SYS_STATUS``
  (2 Hz); where ArduPilot refuses it, ``REQUEST_DATA_STREAM`` (POSITION,
  EXTRA1 -> ``ATTITUDE``, EXTENDED_STATUS) as the fallback; preflight
  names every vehicle that does not stream its position, attitude or
  landed state, with the message and the answer it gave;
* **fail-safe parameters checked**: preflight reads with
  ``PARAM_REQUEST_READ`` PX4's ``COM_OF_LOSS_T``, ``COM_OBL_RC_ACT``,
  ``COM_RC_IN_MODE``, ``NAV_DLL_ACT`` or ArduPilot's ``FS_GCS_ENABLE``,
  ``FS_GCS_TIMEOUT``, ``GUID_TIMEOUT``, ``FS_OPTIONS`` and its GCS system
  id, and refuses a vehicle whose own loss action would leave it flying
  (``allow_unsafe_failsafe=True`` overrides, on purpose);
* **one set-point sender** at exactly ``stream_rate``: the diagram updates
  each vehicle's latest set-point, the sender thread streams it (and a
  GCS ``HEARTBEAT`` at 1 Hz); a set-point older than ``hold`` is not
  re-sent, so a hung commander is caught by the vehicle's own
  offboard-loss action;
* **commands**: ``COMMAND_LONG`` whose ``COMMAND_ACK`` is awaited;
  no answer -> re-sent with the confirmation counter (``retries``);
  ``TEMPORARILY_REJECTED`` -> tried again until ``retry_budget`` seconds
  are spent; ``IN_PROGRESS`` -> the final answer is awaited (same
  budget); a refusal raises :class:`~avblocks.interfaces.flight.FlightError`
  naming the vehicle, the command, the result and the vehicle's last
  ``STATUSTEXT``;
* **takeoff**: PX4 streams a position set-point at the vehicle's position
  for ``prestream`` s (PX4 enables offboard only after more than a second
  of set-points), switches to OFFBOARD, arms and streams the set-point
  ``takeoff_height`` above; ArduPilot switches to GUIDED (mode 4), arms
  and sends ``NAV_TAKEOFF``; both wait until every vehicle is within
  0.1 m of its height and climbs slower than 0.15 m/s;
* **mission**: velocity set-points as ``SET_POSITION_TARGET_LOCAL_NED`` in
  ``MAV_FRAME_LOCAL_NED`` (type mask 1479: velocity and yaw rate 0 used);
* **land / fail-safe**: ``NAV_LAND`` (or ``NAV_RETURN_TO_LAUNCH``) to every
  vehicle, three times, acknowledgements not awaited.
"""

from __future__ import annotations

import math
import threading
import time

import numpy as np

from ...core.errors import ParameterError
from ..flight import Fleet, FleetLink, FlightError, PreflightError, TelemetryBuffer
from . import autopilots as ap
from . import frames
from .autopilots import APM_MODES, PX4_MODES
from .emulator import CMD_ARM, CMD_DO_SET_MODE, CMD_LAND, CMD_RTL, CMD_TAKEOFF, mavutil

#: SET_POSITION_TARGET_LOCAL_NED type masks (bits set = ignored).
MASK_VELOCITY = 1 | 2 | 4 | 64 | 128 | 256 | 1024          # 1479: vx vy vz, yaw rate
MASK_POSITION = 8 | 16 | 32 | 64 | 128 | 256 | 1024        # 1528: x y z, yaw rate
RESULTS = ap.RESULT
COMMANDS = {CMD_ARM: "ARM", CMD_DO_SET_MODE: "DO_SET_MODE", CMD_TAKEOFF: "NAV_TAKEOFF",
            CMD_LAND: "NAV_LAND", CMD_RTL: "NAV_RETURN_TO_LAUNCH",
            511: "SET_MESSAGE_INTERVAL"}
#: connection-string prefixes accepted (pymavlink's, plus ``serial:DEV:BAUD``)
PREFIXES = ("udpin:", "udpout:", "udp:", "udpbcast:", "tcp:", "tcpin:", "serial:")

#: what the commander reads, each a quantity with the messages that carry
#: it (the first is the one asked for) and the rate asked
QUANTITIES = {"position": (("LOCAL_POSITION_NED", "ODOMETRY"), None),
              "attitude": (("ATTITUDE_QUATERNION", "ODOMETRY", "ATTITUDE"), None),
              "landed state": (("EXTENDED_SYS_STATE",), 5.0)}
#: asked for too, not required (a vehicle without a battery report flies)
OPTIONAL = {"SYS_STATUS": 2.0}
#: ArduPilot's REQUEST_DATA_STREAM fallback: MAV_DATA_STREAM id -> messages
FALLBACK_STREAMS = {6: "LOCAL_POSITION_NED", 10: "ATTITUDE", 2: "SYS_STATUS"}


#: PX4 main modes (px4_custom_mode.h) and AUTO sub modes, for messages
PX4_MAIN = {1: "MANUAL", 2: "ALTCTL", 3: "POSCTL", 4: "AUTO", 5: "ACRO", 6: "OFFBOARD",
            7: "STABILIZED", 8: "RATTITUDE"}
PX4_AUTO = {1: "READY", 2: "TAKEOFF", 3: "LOITER", 4: "MISSION", 5: "RTL", 6: "LAND",
            8: "FOLLOW_TARGET", 9: "PRECLAND"}
#: EXTENDED_SYS_STATE.landed_state values of a vehicle off the ground
#: (MAV_LANDED_STATE: 2 IN_AIR, 3 TAKEOFF, 4 LANDING)
IN_AIR_STATES = {2: "IN_AIR", 3: "TAKEOFF", 4: "LANDING"}
#: Status texts / malformed messages logged per vehicle and second at most
#: (the rest counted: a flood must not grow the flight log without bound)
LOG_PER_SECOND = 10


def mode_name(autopilot, custom_mode):
    """``"OFFBOARD"``, ``"AUTO.LAND"``, ``"GUIDED"`` ... of a HEARTBEAT's
    custom mode."""
    if autopilot == "px4":
        main, sub = (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF
        name = PX4_MAIN.get(main, f"main mode {main}")
        return f"{name}.{PX4_AUTO.get(sub, sub)}" if main == 4 else name
    names = {v: k.upper() for k, v in APM_MODES.items()}
    return names.get(custom_mode, f"mode {custom_mode}")


class _Throttle:
    """At most ``per_second`` records per key and second; the rest counted
    and reported in the next record of that key (``suppressed``)."""

    def __init__(self, record, per_second=LOG_PER_SECOND):
        self.record, self.per_second = record, int(per_second)
        self._win = {}          # key -> (window start, count, suppressed)
        self._lock = threading.Lock()

    def __call__(self, key, ev, **kw):
        now = time.monotonic()
        with self._lock:
            t0, k, skipped = self._win.get(key, (now, 0, 0))
            if now - t0 >= 1.0:
                t0, k = now, 0
            if k >= self.per_second:
                self._win[key] = (t0, k, skipped + 1)
                return
            self._win[key] = (t0, k + 1, 0)
        if skipped:
            kw["suppressed_before"] = skipped
        self.record(ev, **kw)

    def flush(self):
        with self._lock:
            left = {k: v[2] for k, v in self._win.items() if v[2]}
            self._win.clear()
        for key, n in left.items():
            self.record("suppressed", key=list(key), count=n)


class MavlinkLink(FleetLink):
    """The MAVLink side of :class:`Drones` (see the module docstring)."""

    def __init__(self, names, connections, origins, *, stream_rate=20.0, hold=0.5,
                 ack_timeout=1.0, retries=3, source_system=255, source_component=190,
                 record=None, telemetry_rate=30.0, prestream=1.5, retry_budget=5.0,
                 ekf_origin=None, allow_unsafe_failsafe=False, loss_timeout_max=3.0,
                 wait=10.0):
        self.names, self.conn_strings = names, connections
        self.n = n = len(names)
        self.origins = origins
        self.telemetry = TelemetryBuffer(n)
        self.stream_rate, self.hold = float(stream_rate), float(hold)
        self.telemetry_rate = float(telemetry_rate)
        self.ack_timeout, self.retries = float(ack_timeout), int(retries)
        self.prestream, self.retry_budget = float(prestream), float(retry_budget)
        self.ekf_origin = ekf_origin
        self.allow_unsafe_failsafe = bool(allow_unsafe_failsafe)
        self.loss_timeout_max = float(loss_timeout_max)
        self.wait = float(wait)
        self.src = (source_system, source_component)
        self.record = record or (lambda *a, **k: None)
        self.conns = []
        self.sysid = [0] * n
        self.compid = [ap.COMP_AUTOPILOT1] * n
        self.autopilot = [None] * n            # "px4" | "ardupilot" | "other"
        self.autopilot_id = [None] * n
        self.vtype = [None] * n
        self.seen = [dict() for _ in range(n)]   # message name -> count (autopilot's)
        self.others = [set() for _ in range(n)]  # (component, type) of other components
        self.interval_results = [dict() for _ in range(n)]
        self.fallback = [[] for _ in range(n)]
        self.params = [dict() for _ in range(n)]
        self._asked = set()                     # parameter names asked for
        self._t_quat = np.full(n, -np.inf)
        self._hb = [None] * n                  # (armed, custom mode, monotonic time)
        self._landed_state = [0] * n           # EXTENDED_SYS_STATE.landed_state
        self._want_mode = [None] * n           # (mode name, since) set by the block
        self._want_armed = [None] * n          # since (monotonic) the block armed it
        self._log_some = _Throttle(self.record)
        self._t_reached = np.full(n, np.inf)   # our first heartbeat the vehicle can hear
        self._acks = [dict() for _ in range(n)]  # cmd -> (result, sequence)
        self._ack_seq = 0
        self._ack_cv = threading.Condition()
        self._param_cv = threading.Condition()
        self._send_lock = [threading.Lock() for _ in range(n)]
        self._sp = [None] * n               # (mask, ned xyz, t_monotonic)
        self._streaming = False
        self._hover = False
        self._landing = False
        self._stop = threading.Event()
        self._threads = []
        self._setup = []
        #: Set-points sent, per vehicle (the sender's count).
        self.setpoints_sent = np.zeros(n, np.int64)
        #: Messages of each vehicle dropped as malformed (non-finite numbers,
        #: a quaternion far from unit length, fields pymavlink could not read).
        self.malformed = np.zeros(n, np.int64)

    # -------------------------------------------------------------- plumbing
    def _connect(self, spec):
        m = self.m
        kw = dict(source_system=self.src[0], source_component=self.src[1])
        if spec.startswith(("udpin:", "udp:", "udpout:")):
            from ._udp import UdpLink
            from .emulator import _dialect
            return UdpLink(spec, _dialect(), source_system=self.src[0],
                           source_component=self.src[1])
        if spec.startswith("serial:"):
            dev, _, baud = spec[len("serial:"):].rpartition(":")
            return m.mavlink_connection(dev, baud=int(baud), **kw)
        return m.mavlink_connection(spec, **kw)

    def open(self):
        self.m = mavutil()
        for nm, s in zip(self.names, self.conn_strings):
            try:
                self.conns.append(self._connect(s))
            except (OSError, ValueError, OverflowError) as e:
                why = getattr(e, "strerror", None) or str(e)
                hint = {"udp": "another program (a second avblocks commander, QGroundControl, "
                               "MAVProxy) already listens there: stop it, or give another port",
                        "tcp": "is the vehicle (ArduPilot SITL: tcp:127.0.0.1:5760+10) "
                               "running and serving that port?",
                        "ser": "is the radio plugged in, and is the device name right "
                               "(ls /dev/ttyUSB* /dev/ttyACM*)?"}.get(s[:3], "")
                raise PreflightError(f"{nm}: cannot open the connection {s!r} ({why}); "
                                     "nothing was commanded", block="Drones",
                                     hint=hint) from None
        for i in range(self.n):
            self._heartbeat(i)           # udpout / tcp: the vehicle learns where we are
        for i in range(self.n):
            th = threading.Thread(target=self._rx, args=(i,), daemon=True,
                                  name=f"avblocks-mavlink-rx-{self.names[i]}")
            th.start()
            self._threads.append(th)
        th = threading.Thread(target=self._tx, daemon=True, name="avblocks-mavlink-tx")
        th.start()
        self._threads.append(th)
        for i in range(self.n):
            th = threading.Thread(target=self._set_up, args=(i,), daemon=True,
                                  name=f"avblocks-mavlink-setup-{self.names[i]}")
            th.start()
            self._setup.append(th)

    def _send(self, i, fn, *args, wait=True):
        lock = self._send_lock[i]
        got = lock.acquire(timeout=0.2 if wait else 0.05)
        try:
            getattr(self.conns[i].mav, fn)(*args)
        except Exception:  # noqa: BLE001 - a closing socket, a full serial buffer
            pass
        finally:
            if got:
                lock.release()

    def _heartbeat(self, i):
        self._send(i, "heartbeat_send", ap.TYPE_GCS, ap.AUTOPILOT_INVALID, 0, 0, 4)

    # -------------------------------------------------------------- receiving
    def _rx(self, i):
        c = self.conns[i]
        while not self._stop.is_set():
            try:
                msg = c.recv_match(blocking=True, timeout=0.1)
            except Exception:  # noqa: BLE001 - socket closed on shutdown, bad bytes
                if self._stop.is_set():
                    return
                time.sleep(0.01)
                continue
            if msg is None or msg.get_type() == "BAD_DATA":
                continue
            try:
                self._handle(i, msg)
            except Exception as e:  # noqa: BLE001 - a malformed message is dropped
                self.malformed[i] += 1
                self._log_some((i, "rx_error"), "rx_error", vehicle=self.names[i],
                               type=msg.get_type(), error=f"{type(e).__name__}: {e}")

    def _handle(self, i, msg):
        typ = msg.get_type()
        sid, cid = msg.get_srcSystem(), msg.get_srcComponent()
        if typ == "HEARTBEAT":
            if msg.type == ap.TYPE_GCS:
                return                                   # another ground station
            is_autopilot = (cid == ap.COMP_AUTOPILOT1
                            and msg.autopilot != ap.AUTOPILOT_INVALID)
            if not is_autopilot:
                if sid == self.sysid[i] or self.sysid[i] == 0:
                    if (cid, msg.type) not in self.others[i]:
                        self.others[i].add((cid, msg.type))
                        self.record("component", vehicle=self.names[i], system=sid,
                                    component=cid, mav_type=msg.type,
                                    autopilot=msg.autopilot, note="not the autopilot: "
                                    "its heartbeat is not used")
                return
            if self.sysid[i] == 0:
                self.sysid[i], self.compid[i] = sid, cid
                peer = getattr(self.conns[i], "peer", None)
                self.record("autopilot", vehicle=self.names[i], system=sid, component=cid,
                            autopilot=msg.autopilot, mav_type=msg.type,
                            **({"address": f"{peer[0]}:{peer[1]}"} if peer else {}))
                self._heartbeat(i)        # udpin: now it can reach the vehicle
                self._t_reached[i] = time.monotonic()
            if (sid, cid) != (self.sysid[i], self.compid[i]):
                return
            self.autopilot_id[i] = msg.autopilot
            self.autopilot[i] = ("px4" if msg.autopilot == ap.AUTOPILOT_PX4 else "ardupilot"
                                 if msg.autopilot == ap.AUTOPILOT_ARDUPILOTMEGA else "other")
            self.vtype[i] = msg.type
            self._hb[i] = (bool(msg.base_mode & 128), int(msg.custom_mode), time.monotonic())
        if self.sysid[i] == 0 or (sid, cid) != (self.sysid[i], self.compid[i]):
            return                                       # not this vehicle's autopilot
        now = time.monotonic()
        tb = self.telemetry
        tb.heard(i, now)
        self.seen[i][typ] = self.seen[i].get(typ, 0) + 1
        if typ == "HEARTBEAT":
            armed = bool(msg.base_mode & 128)
            tb.armed(i, armed, None if armed else True)
        elif typ == "LOCAL_POSITION_NED":
            _check(typ, msg.x, msg.y, msg.z, msg.vx, msg.vy, msg.vz)
            tb.pose(i, frames.position_to_world([msg.x, msg.y, msg.z], self.origins[i]),
                    frames.ned_to_enu([msg.vx, msg.vy, msg.vz]), now)
        elif typ == "ODOMETRY" and msg.frame_id == 1:         # pose in MAV_FRAME_LOCAL_NED
            _check(typ, msg.x, msg.y, msg.z, msg.vx, msg.vy, msg.vz)
            q = frames.quat_to_enu(_unit(typ, msg.q))
            v = np.array([msg.vx, msg.vy, msg.vz])
            if msg.child_frame_id != 1:      # velocity in the body frame (BODY_FRD, 12)
                v = _rotmat(_unit(typ, msg.q)) @ v
            tb.pose(i, frames.position_to_world([msg.x, msg.y, msg.z], self.origins[i]),
                    frames.ned_to_enu(v), now)
            tb.attitude(i, q)
            self._t_quat[i] = now
        elif typ == "ATTITUDE_QUATERNION":
            tb.attitude(i, frames.quat_to_enu(_unit(typ, [msg.q1, msg.q2, msg.q3, msg.q4])))
            self._t_quat[i] = now
        elif typ == "ATTITUDE" and now - self._t_quat[i] > 0.5:   # Euler: the fallback
            _check(typ, msg.roll, msg.pitch, msg.yaw)
            tb.attitude(i, frames.quat_to_enu(_euler_quat(msg.roll, msg.pitch, msg.yaw)))
        elif typ in ("SYS_STATUS", "BATTERY_STATUS") and msg.battery_remaining >= 0:
            tb.battery(i, min(msg.battery_remaining, 100) / 100.0)
        elif typ == "EXTENDED_SYS_STATE" and msg.landed_state:
            self._landed_state[i] = int(msg.landed_state)
            tb.armed(i, tb.snapshot().armed[i], msg.landed_state == 1)
        elif typ == "STATUSTEXT":
            text = msg.text if isinstance(msg.text, str) else msg.text.decode(
                errors="replace")
            text = text.rstrip("\x00")[:200]
            tb.status(i, text)
            self._log_some((i, "statustext"), "statustext", vehicle=self.names[i], text=text)
        elif typ == "COMMAND_ACK":
            tgt = getattr(msg, "target_system", 0)
            if tgt not in (0, self.src[0]):
                return                               # meant for another ground station
            with self._ack_cv:
                self._ack_seq += 1
                self._acks[i][msg.command] = (msg.result, self._ack_seq)
                self._ack_cv.notify_all()
        elif typ == "PARAM_VALUE":
            name = msg.param_id if isinstance(msg.param_id, str) else msg.param_id.decode(
                errors="replace")
            name = name.split("\x00")[0]
            if name not in self._asked:
                return                      # only what was asked for is kept
            value = ap.decode_param(msg.param_value, msg.param_type, self.autopilot[i])
            with self._param_cv:
                self.params[i][name] = value
                self._param_cv.notify_all()

    # -------------------------------------------------------------- sending
    def _tx(self):
        """The one sender: set-points at exactly ``stream_rate`` (absolute
        schedule, no catch-up bursts) and GCS heartbeats at 1 Hz."""
        period = 1.0 / self.stream_rate
        t_next = time.monotonic()
        next_hb = t_next + 1.0
        while not self._stop.is_set():
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
            t_next += period
            if t_next < now - period:      # fell behind (a loaded machine): resume
                t_next = now + period
            self._stop.wait(max(0.0, t_next - time.monotonic()))

    def _setpoint(self, i, mask, xyz):
        ms = int(time.monotonic() * 1000) & 0xFFFFFFFF
        pos = xyz if mask == MASK_POSITION else (0.0, 0.0, 0.0)
        vel = xyz if mask == MASK_VELOCITY else (0.0, 0.0, 0.0)
        self._send(i, "set_position_target_local_ned_send", ms, self.sysid[i] or 1,
                   self.compid[i], 1, mask, *map(float, pos), *map(float, vel),
                   0.0, 0.0, 0.0, 0.0, 0.0)
        self.setpoints_sent[i] += 1

    def _ack_state(self, i, cmd):
        with self._ack_cv:
            return self._acks[i].get(cmd, (None, 0))[1]

    def _await_ack(self, i, cmd, after, timeout):
        deadline = time.monotonic() + timeout
        with self._ack_cv:
            while True:
                res, seq = self._acks[i].get(cmd, (None, 0))
                if seq > after:
                    return res, seq
                left = deadline - time.monotonic()
                if left <= 0:
                    return None, after
                self._ack_cv.wait(min(left, 0.05))

    def command(self, i, cmd, *params, what=None, raise_on_refusal=True):
        """``COMMAND_LONG`` to vehicle ``i``; returns the final ``MAV_RESULT``
        (0 ACCEPTED). No answer: re-sent with the confirmation counter, up to
        ``retries`` times; ``TEMPORARILY_REJECTED``: tried again until
        ``retry_budget`` s are spent; ``IN_PROGRESS``: the final answer is
        awaited (same budget). Anything else, or the budget spent, raises
        FlightError naming the vehicle, the command and the reason (or, with
        ``raise_on_refusal=False``, returns the result; None: no answer)."""
        p = list(params) + [0.0] * (7 - len(params))
        what = what or COMMANDS.get(cmd, str(cmd))
        t0 = time.monotonic()
        budget_end = t0 + self.retry_budget
        tries = confirmation = 0
        while True:
            seq = self._ack_state(i, cmd)
            self._send(i, "command_long_send", self.sysid[i] or 1, self.compid[i], cmd,
                       confirmation, *p)
            tries += 1
            res, seq = self._await_ack(i, cmd, seq, self.ack_timeout)
            while res == ap.IN_PROGRESS and time.monotonic() < budget_end:
                self.record("ack", vehicle=self.names[i], command=what, result="IN_PROGRESS")
                res, seq = self._await_ack(i, cmd, seq, budget_end - time.monotonic())
            if res is None:
                confirmation += 1
                if confirmation < max(1, self.retries) and time.monotonic() < budget_end:
                    continue
                msg = (f"{self.names[i]} did not acknowledge {what} within "
                       f"{confirmation} x {self.ack_timeout:g} s")
                self.record("no_ack", vehicle=self.names[i], command=what)
                if not raise_on_refusal:
                    return None
                raise FlightError(msg, block="Drones", hint="is the vehicle connected and "
                                  "the connection string right?")
            if res == ap.ACCEPTED:
                self.record("ack", vehicle=self.names[i], command=what, result="ACCEPTED",
                            tries=tries)
                return res
            if res == ap.TEMPORARILY_REJECTED and time.monotonic() + 0.25 < budget_end:
                self.record("ack", vehicle=self.names[i], command=what,
                            result="TEMPORARILY_REJECTED", tries=tries)
                time.sleep(0.25)
                confirmation = 0
                continue
            time.sleep(0.1)             # the STATUSTEXT comes with the ack
            text = self.telemetry.snapshot().status[i]
            name = RESULTS.get(res, str(res))
            self.record("refused", vehicle=self.names[i], command=what, result=name,
                        text=text, tries=tries)
            if not raise_on_refusal:
                return res
            spent = (f" {tries} times in {time.monotonic() - t0:.1f} s (retry_budget "
                     f"{self.retry_budget:g} s)" if res == ap.TEMPORARILY_REJECTED
                     or res == ap.IN_PROGRESS else "")
            raise FlightError(f"{self.names[i]} refused {what}: {name}{spent}"
                              + (f" ('{text}')" if text else ""),
                              block="Drones", hint="see the vehicle's messages")

    def _in_mode(self, i, name, custom_mode):
        if self.autopilot[i] == "px4":
            main, sub = PX4_MODES[name]
            return (custom_mode >> 16) & 0xFF == main and (
                main != 4 or (custom_mode >> 24) & 0xFF == sub)
        return custom_mode == APM_MODES[name]

    def lost_control(self):
        """Vehicles whose HEARTBEAT, sent after the block put them in their
        mode and armed them, says they are disarmed or in another mode (their
        own fail-safe, a pilot, another ground station took them)."""
        if self._landing:
            return []
        out = []
        for i, nm in enumerate(self.names):
            hb = self._hb[i]
            if hb is None:
                continue
            armed, cm, t = hb
            wa, wm = self._want_armed[i], self._want_mode[i]
            if wa is not None and t > wa and not armed:
                out.append((i, f"{nm} is disarmed (mode {mode_name(self.autopilot[i], cm)}; "
                               "its own fail-safe, a pilot or another ground station?)"))
            elif wm is not None and t > wm[1] and not self._in_mode(i, wm[0], cm):
                out.append((i, f"{nm} left {wm[0].upper()} for "
                               f"{mode_name(self.autopilot[i], cm)} (its own fail-safe, a "
                               "pilot or another ground station?)"))
        return out

    def set_mode(self, i, name):
        if self.autopilot[i] == "ardupilot":
            self.command(i, CMD_DO_SET_MODE, 1, APM_MODES[name],
                         what=f"DO_SET_MODE ({name.upper()})")
        elif self.autopilot[i] == "px4":
            main, sub = PX4_MODES[name]
            self.command(i, CMD_DO_SET_MODE, 1, main, sub, what=f"DO_SET_MODE ({name.upper()})")
        else:               # preflight refuses these; never guess mode numbers
            raise FlightError(f"{self.names[i]}: autopilot {self.autopilot_id[i]} is neither "
                              "PX4 nor ArduPilot; no mode was sent", block="Drones")

    # -------------------------------------------------------------- set-up
    def _set_up(self, i):
        """Per vehicle, before preflight: wait for the autopilot's heartbeat,
        send the EKF origin if given, ask for the telemetry, read the
        fail-safe parameters."""
        deadline = time.monotonic() + self.wait
        while self.autopilot[i] is None and time.monotonic() < deadline \
                and not self._stop.is_set():
            time.sleep(0.02)
        if self.autopilot[i] not in ("px4", "ardupilot"):
            return
        if self.ekf_origin is not None:
            lat, lon, alt = self.ekf_origin
            for _ in range(3):
                self._send(i, "set_gps_global_origin_send", self.sysid[i],
                           int(round(lat * 1e7)), int(round(lon * 1e7)),
                           int(round(alt * 1000)))
                time.sleep(0.05)
            self.record("ekf_origin", vehicle=self.names[i], lat=lat, lon=lon, alt=alt)
        self._request_streams(i)
        self._read_failsafe_params(i)

    def _request_streams(self, i):
        asked = {names[0]: rate or self.telemetry_rate
                 for names, rate in QUANTITIES.values()}
        asked.update(OPTIONAL)
        res = self.interval_results[i]
        for name, hz in asked.items():
            r = self.command(i, 511, ap.MSG[name], 1e6 / hz, 0, 0, 0, 0, 0,
                             what=f"SET_MESSAGE_INTERVAL ({name})", raise_on_refusal=False)
            res[name] = "no answer" if r is None else RESULTS.get(r, str(r))
        refused = [k for k, v in res.items() if v != "ACCEPTED"]
        if refused and self.autopilot[i] == "ardupilot":
            for sid, name in FALLBACK_STREAMS.items():
                hz = asked.get(name, self.telemetry_rate)
                for _ in range(2):
                    self._send(i, "request_data_stream_send", self.sysid[i], self.compid[i],
                               sid, max(1, int(round(hz))), 1)
                self.fallback[i].append(ap.APM_STREAM_NAMES[sid])
        self.record("streams", vehicle=self.names[i], set_message_interval=res,
                    request_data_stream=self.fallback[i])

    def read_params(self, i, groups, timeout=None):
        """``{last name of each group: value or None}``: for each group of
        alternative names (``("MAV_GCS_SYSID", "SYSID_MYGCS")``), the value of
        the first vehicle ``i`` answers for (``PARAM_REQUEST_READ``, all asked
        at once, the unanswered again, ``retries`` rounds)."""
        timeout = self.ack_timeout if timeout is None else timeout

        def value(names):
            for nm in names:
                if nm in self.params[i]:
                    return self.params[i][nm]
            return None
        for _ in range(max(1, self.retries)):
            todo = [g for g in groups if value(g) is None]
            if not todo:
                break
            for g in todo:
                for nm in g:
                    self._asked.add(nm)
                    self._send(i, "param_request_read_send", self.sysid[i],
                               self.compid[i], nm.encode(), -1)
            deadline = time.monotonic() + timeout
            with self._param_cv:
                while time.monotonic() < deadline and any(value(g) is None for g in todo):
                    self._param_cv.wait(0.05)
        with self._param_cv:
            return {g[-1]: value(g) for g in groups}

    def _read_failsafe_params(self, i):
        if self.autopilot[i] == "px4":
            wanted = [("COM_OF_LOSS_T",), ("COM_OBL_RC_ACT",), ("COM_RC_IN_MODE",),
                      ("NAV_DLL_ACT",)]
        else:       # 4.7 renamed SYSID_MYGCS to MAV_GCS_SYSID
            wanted = [("FS_GCS_ENABLE",), ("FS_GCS_TIMEOUT",), ("GUID_TIMEOUT",),
                      ("FS_OPTIONS",), ("MAV_GCS_SYSID", "SYSID_MYGCS")]
        got = self.read_params(i, wanted)
        self.record("failsafe_params", vehicle=self.names[i], autopilot=self.autopilot[i],
                    values=got)

    def _failsafe_problems(self, i):
        nm = self.names[i]
        p = self.params[i]
        out = []
        if self.autopilot[i] == "px4":
            tab = ap.PX4_PARAMS
            act = p.get("COM_OBL_RC_ACT")
            if act is None:
                out.append(f"{nm}: could not read COM_OBL_RC_ACT (no PARAM_VALUE): what it "
                           "does when the set-points stop is unknown")
            elif act in ap.PX4_FLYING_LOSS_ACTIONS or act < 0:
                out.append(f"{nm}: COM_OBL_RC_ACT = {ap.describe(tab, 'COM_OBL_RC_ACT', act)}"
                           ": when the set-points stop it keeps flying (a pilot's RC, or "
                           "hovering); set 4 (Land mode) or 3 (Return mode)")
            t = p.get("COM_OF_LOSS_T")
            if t is None:
                out.append(f"{nm}: could not read COM_OF_LOSS_T (no PARAM_VALUE)")
            elif t > self.loss_timeout_max:
                out.append(f"{nm}: COM_OF_LOSS_T = {t:g} s: it flies on its last set-point "
                           f"that long after they stop (at most loss_timeout_max "
                           f"{self.loss_timeout_max:g} s)")
            elif t * self.stream_rate < 2.5:
                out.append(f"{nm}: COM_OF_LOSS_T = {t:g} s is shorter than 2.5 set-point "
                           f"periods at stream_rate {self.stream_rate:g} Hz")
            return out
        tab = ap.APM_PARAMS
        fs = p.get("FS_GCS_ENABLE")
        if fs is None:
            out.append(f"{nm}: could not read FS_GCS_ENABLE (no PARAM_VALUE): what it does "
                       "when the ground station goes quiet is unknown")
        elif fs in ap.APM_FLYING_GCS_ACTIONS:
            out.append(f"{nm}: FS_GCS_ENABLE = {ap.describe(tab, 'FS_GCS_ENABLE', fs)}: "
                       "when the commander stops, GUIDED only stops the vehicle after "
                       "GUID_TIMEOUT and it hovers until its battery fails; set 5 (Land)")
        g = p.get("GUID_TIMEOUT")
        if g is not None and g > self.loss_timeout_max:
            out.append(f"{nm}: GUID_TIMEOUT = {g:g} s: it flies on its last velocity that "
                       f"long (at most loss_timeout_max {self.loss_timeout_max:g} s)")
        gcs = p.get("MAV_GCS_SYSID", p.get("SYSID_MYGCS"))
        if gcs is not None and int(gcs) != self.src[0]:
            out.append(f"{nm}: its GCS failsafe watches system {int(gcs)}'s heartbeats "
                       f"(SYSID_MYGCS / MAV_GCS_SYSID), this commander sends as system "
                       f"{self.src[0]}")
        return out

    def preflight(self, telemetry):
        """Set-up finished; every vehicle streams what the commander reads;
        its fail-safe parameters end a flight when the commander stops."""
        deadline = time.monotonic() + self.wait
        for th in self._setup:
            th.join(max(0.0, deadline - time.monotonic()))
        # the asked-for streams: give them 2 s after the set-up
        t_end = min(deadline, time.monotonic() + 2.0)
        while time.monotonic() < t_end and self._missing():
            time.sleep(0.05)
        why = []
        for i, nm in enumerate(self.names):
            if self.autopilot[i] is None:
                others = ", ".join(f"component {c} (MAV_TYPE {t})"
                                   for c, t in sorted(self.others[i]))
                if others:
                    why.append(f"{nm}: no HEARTBEAT from an autopilot (component 1, "
                               f"autopilot not MAV_AUTOPILOT_INVALID), only from {others}")
                continue
            if self.autopilot[i] == "other":
                why.append(f"{nm}: autopilot MAV_AUTOPILOT {self.autopilot_id[i]} is "
                           "neither PX4 (12) nor ArduPilot (3): its modes are unknown")
                continue
            if self.vtype[i] not in ap.MULTICOPTER_TYPES:
                why.append(f"{nm}: MAV_TYPE {self.vtype[i]} is not a multicopter")
            ls = self._landed_state[i]
            if ls in IN_AIR_STATES:
                hb = self._hb[i]
                mode = mode_name(self.autopilot[i], hb[1]) if hb else "unknown"
                why.append(f"{nm}: already off the ground (EXTENDED_SYS_STATE "
                           f"{IN_AIR_STATES[ls]}, z={telemetry.position[i, 2]:.2f} m, mode "
                           f"{mode}): a pilot or another ground station flies it; land it "
                           "first")
            for q in self._missing(i):
                names = QUANTITIES[q][0]
                first = names[0]
                how = f"SET_MESSAGE_INTERVAL {self.interval_results[i].get(first, 'not sent')}"
                if self.fallback[i]:
                    how += (f"; REQUEST_DATA_STREAM {', '.join(self.fallback[i])} sent, "
                            f"no {' / '.join(names[1:]) or first} either")
                why.append(f"{nm}: does not stream {first} ({q}; {how})")
            fs = self._failsafe_problems(i)
            if fs and self.allow_unsafe_failsafe:
                self.record("unsafe_failsafe_allowed", vehicle=nm, problems=fs)
            else:
                why += fs
        return why

    def _missing(self, i=None):
        """Quantities vehicle ``i`` (default: any vehicle with an autopilot)
        has not streamed yet."""
        if i is None:
            return [q for k in range(self.n) if self.autopilot[k] in ("px4", "ardupilot")
                    for q in self._missing(k)]
        return [q for q, (names, _) in QUANTITIES.items()
                if not any(self.seen[i].get(m) for m in names)]

    # -------------------------------------------------------------- phases
    def takeoff(self, height, timeout):
        quiet = [nm for nm, a in zip(self.names, self.autopilot)
                 if a not in ("px4", "ardupilot")]
        if quiet:
            raise FlightError(f"no PX4 or ArduPilot autopilot heard from {quiet}; nothing "
                              "was armed", block="Drones")
        tm = self.telemetry.snapshot()
        start = tm.position.copy()
        goal = start + [0.0, 0.0, height]
        self._landing = False
        self._want_mode, self._want_armed = [None] * self.n, [None] * self.n
        px4 = [i for i in range(self.n) if self.autopilot[i] == "px4"]
        for i in range(self.n):     # PX4: set-points must flow before OFFBOARD
            local = frames.position_to_local(start[i], self.origins[i])
            self._sp[i] = ((MASK_POSITION, local, time.monotonic()) if i in px4 else None)
        self._streaming = True
        self._hover = True      # re-send whatever the age while this phase runs
        if px4:
            # PX4 enables offboard only after more than a second of set-points
            # (offboard mode page); prestream > 1 s at stream_rate > 2 Hz
            self.record("prestream", vehicles=[self.names[i] for i in px4],
                        seconds=self.prestream, rate=self.stream_rate)
            time.sleep(self.prestream)
        apm = [i for i in range(self.n) if self.autopilot[i] == "ardupilot"]
        if apm:
            # ArduCopter clears a GCS failsafe left on by an earlier commander
            # in its 3 Hz check after our heartbeat (events.cpp); until then
            # it refuses to arm ("GCS failsafe on"): heartbeats for 1 s first
            t_ok = max(self._t_reached[i] for i in apm) + 1.0
            time.sleep(max(0.0, min(t_ok - time.monotonic(), 2.0)))
        for i in range(self.n):
            mode = "guided" if self.autopilot[i] == "ardupilot" else "offboard"
            self.set_mode(i, mode)
            self._want_mode[i] = (mode, time.monotonic())
            self.command(i, CMD_ARM, 1)
            self._want_armed[i] = time.monotonic()
            if self.autopilot[i] == "ardupilot":
                self.command(i, CMD_TAKEOFF, 0, 0, 0, 0, 0, 0, float(height))
            else:
                local = frames.position_to_local(goal[i], self.origins[i])
                self._sp[i] = (MASK_POSITION, local, time.monotonic())
            self.record("climb", vehicle=self.names[i], goal=goal[i].tolist())
        deadline = time.monotonic() + timeout
        while True:
            tm = self.telemetry.snapshot()
            lost = self.lost_control()
            silent = [nm for nm, a in zip(self.names, tm.heard_age) if a > self.link_timeout]
            if lost or silent:
                raise FlightError(
                    "the takeoff failed: " + "; ".join(
                        [why for _, why in lost]
                        + ([f"nothing heard from {silent} for more than link_timeout "
                            f"{self.link_timeout:g} s"] if silent else [])),
                    block="Drones", hint="the vehicles still heard are commanded to land")
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
        """The latest velocity set-points; the sender thread streams them."""
        if self._landing:
            return
        ned = frames.enu_to_ned(np.asarray(v, float))
        now = time.monotonic()
        self._hover = False
        for i in range(self.n):
            self._sp[i] = (MASK_VELOCITY, ned[i], now)

    def land(self, action="land"):
        self._landing = True
        self._streaming = False
        self._hover = False
        cmd = CMD_RTL if action == "rtl" else CMD_LAND
        for k in range(3):
            for i in range(self.n):
                if i < len(self.conns):
                    self._send(i, "command_long_send", self.sysid[i] or 1, self.compid[i],
                               cmd, k, 0, 0, 0, float("nan"), float("nan"), float("nan"),
                               float("nan"), wait=False)
            if k < 2:
                time.sleep(0.02)

    def close(self):
        self._stop.set()
        for th in self._threads + self._setup:
            th.join(timeout=1.0)
        self._log_some.flush()
        for i, c in enumerate(self.conns):
            if getattr(c, "foreign", 0):
                self.record("foreign_datagrams", vehicle=self.names[i], count=c.foreign,
                            last_from=[f"{h}:{p}" for h, p in c.foreign_from],
                            note="datagrams from addresses other than the vehicle's, "
                                 "dropped unread")
            if self.malformed[i]:
                self.record("malformed", vehicle=self.names[i], count=int(self.malformed[i]))
        for c in self.conns:
            try:
                c.close()
            except Exception:  # noqa: BLE001
                pass


def _check(typ, *values):
    """ValueError unless every number of a message is finite (a NaN
    position must not reach the diagram: a malformed message is dropped)."""
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"{typ} with a non-finite value")


def _unit(typ, q):
    """The unit quaternion of ``q`` (w, x, y, z); ValueError for a
    non-finite one or one far from unit length (norm outside 0.5-1.5)."""
    q = np.asarray(q, float)
    nq = float(np.linalg.norm(q)) if np.isfinite(q).all() else math.nan
    if not 0.5 <= nq <= 1.5:
        raise ValueError(f"{typ} quaternion of norm {nq:.3g}")
    return q / nq


def _rotmat(q):
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _euler_quat(roll, pitch, yaw):
    """(w, x, y, z) of ZYX Euler angles (ATTITUDE: body FRD -> NED)."""
    cr, sr = np.cos(roll / 2), np.sin(roll / 2)
    cp, sp = np.cos(pitch / 2), np.sin(pitch / 2)
    cy, sy = np.cos(yaw / 2), np.sin(yaw / 2)
    return np.array([cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
                     cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy])


def connections_from(spec, n=None):
    """Connection strings of ``spec``: ``"udpin:127.0.0.1:14540+"`` with
    ``n`` -> n strings on consecutive ports; ``"tcp:127.0.0.1:5760+10"`` ->
    ports 5760, 5770, ...; ``"a,b,c"`` -> a list; a list as is."""
    if isinstance(spec, str):
        head, sep, step = spec.rpartition("+")
        if sep and (step == "" or step.isdigit()) and ":" in head:
            if n is None:
                raise ParameterError("a connection 'PREFIX:PORT+' needs the number of "
                                     "vehicles", param="connections", found=spec)
            pre, port = head.rsplit(":", 1)
            if not port.isdigit() or not pre:
                raise ParameterError("a connection 'PREFIX:PORT+' or 'PREFIX:PORT+STEP' "
                                     "ends with a port number", param="connections",
                                     found=spec, expected="udpin:127.0.0.1:14540+ or "
                                                          "tcp:127.0.0.1:5760+10")
            d = int(step or 1)
            return [f"{pre}:{int(port) + d * k}" for k in range(int(n))]
        spec = [s.strip() for s in spec.split(",") if s.strip()]
    return list(spec)


def _check_connection(s):
    if s.startswith("/dev/") or s.startswith("COM"):
        return
    if "://" in s or not s.startswith(PREFIXES):       # "udp://...": MAVSDK's syntax
        raise ParameterError(
            "not a MAVLink connection string this block knows", block="Drones",
            param="connections", found=s,
            expected="udpin:127.0.0.1:14540 (PX4 SITL), tcp:127.0.0.1:5760 (ArduPilot "
                     "SITL), serial:/dev/ttyUSB0:57600 (a radio), udpout:HOST:PORT")
    if s.startswith("serial:"):
        dev, _, baud = s[len("serial:"):].rpartition(":")
        if not dev or not baud.isdigit():
            raise ParameterError("a serial link is serial:DEVICE:BAUD", block="Drones",
                                 param="connections", found=s,
                                 expected="serial:/dev/ttyUSB0:57600")
        return
    host, _, port = s.partition(":")[2].rpartition(":")
    if s.endswith("+") or "+" in port:
        raise ParameterError("PREFIX:PORT+ stands for every vehicle's port on its own; in "
                             "a comma-separated list give each vehicle's port",
                             block="Drones", param="connections", found=s,
                             expected="udpin:127.0.0.1:14540+ or udpin:127.0.0.1:14540,"
                                      "udpin:127.0.0.1:14541")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ParameterError("a network link is PREFIX:HOST:PORT with a port from 1 to "
                             "65535", block="Drones", param="connections", found=s,
                             expected="udpin:127.0.0.1:14540, tcp:127.0.0.1:5760")


class Drones(Fleet):
    """N PX4 or ArduPilot multicopters over MAVLink, with the ports of
    :func:`~avblocks.vehicles.velocity_controlled_quadrotor`.

    Ports
    -----
    velocity : in, (N, 3) [m/s]
        World-frame (ENU) velocity, sent as NED ``SET_POSITION_TARGET_LOCAL_NED``.
    position : out, (N, 3) [m]; pose : out, (N, 3) [m, m, rad]
    attitude : out, (N, 4)
        From ``LOCAL_POSITION_NED``/``ODOMETRY`` and ``ATTITUDE_QUATERNION``
        (or ``ATTITUDE``), converted to ENU / FLU.
    fresh : out, (N,) bool; age : out, (N,) [s]
        As :class:`~avblocks.interfaces.flight.Fleet`.

    Parameters
    ----------
    connections : list of str, "a,b" or "udpin:127.0.0.1:14540+"
        One pymavlink connection string per vehicle; ``PREFIX:PORT+`` gives
        consecutive ports for ``n`` vehicles, ``PREFIX:PORT+STEP`` ports
        STEP apart. PX4 SITL: ``udpin:127.0.0.1:14540+`` (instance i sends
        to 14540 + i); ArduPilot SITL: ``tcp:127.0.0.1:5760+10``; a radio:
        ``serial:/dev/ttyUSB0:57600``. ``udpin`` listens: it binds the
        address named (127.0.0.1 for the same computer).
    names : list of str, optional
        Vehicle names (default ``uav1`` ...).
    n : int, optional
        Number of vehicles, with a ``PORT+`` connection.
    origins : (N, 3), optional
        World (ENU) position of each vehicle's local NED origin [m]
        (default: the world origin).
    stream_rate : float [Hz]
        Set-point rate, exactly (PX4 needs more than 2 Hz).
    hold : float [s]
        The sender stops re-sending a set-point older than this.
    ack_timeout : float [s]; retries : int
        Waiting for each ``COMMAND_ACK``; sends of a command not answered.
    telemetry_rate : float [Hz]
        Rate asked for ``LOCAL_POSITION_NED`` and ``ATTITUDE_QUATERNION``.
    prestream : float [s]
        PX4: set-points streamed before OFFBOARD is asked for (> 1 s).
    retry_budget : float [s]
        How long a ``TEMPORARILY_REJECTED`` command is tried again (and an
        ``IN_PROGRESS`` one awaited).
    ekf_origin : (lat [deg], lon [deg], alt [m AMSL]), optional
        Sent as ``SET_GPS_GLOBAL_ORIGIN`` before preflight (ArduPilot
        indoors, without GPS, has no local position until it has one).
    allow_unsafe_failsafe : bool
        Fly vehicles whose own loss action would leave them flying
        (refused by default).
    loss_timeout_max : float [s]
        Longest ``COM_OF_LOSS_T`` (PX4) / ``GUID_TIMEOUT`` (ArduPilot)
        accepted: how long a vehicle flies on its last set-point.
    **flight
        The shared flight parameters (:class:`~avblocks.interfaces.flight.Fleet`).

    Equations
    ---------
    ``v_ned = (v_y, v_x, -v_z)`` of the shaped world-frame command;
    positions ``p = origin + (y_ned, x_ned, -z_ned)`` (:mod:`.frames`).

    References
    ----------
    MAVLink common message set, command and parameter protocols; PX4
    offboard mode (v1.16) and ``src/modules/commander/``; ArduPilot
    ``libraries/GCS_MAVLink/``, ``ArduCopter/mode.h``,
    ``ArduCopter/Parameters.cpp`` (details in :mod:`.autopilots`).

    Examples
    --------
    >>> from avblocks.interfaces.mavlink import Drones
    >>> b = Drones("udpin:127.0.0.1:14540+", n=2)
    >>> b.names, b.connections
    (['uav1', 'uav2'], ['udpin:127.0.0.1:14540', 'udpin:127.0.0.1:14541'])
    >>> sorted(b.output_ports)
    ['age', 'attitude', 'fresh', 'pose', 'position']
    """

    def __init__(self, connections, names=None, *, n=None, origins=None, stream_rate=20.0,
                 hold=0.5, ack_timeout=1.0, retries=3, telemetry_rate=30.0, prestream=1.5,
                 retry_budget=5.0, ekf_origin=None, allow_unsafe_failsafe=False,
                 loss_timeout_max=3.0, **flight):
        if names is not None and n is None:
            n = len(names.split(",") if isinstance(names, str) else names)
        conns = connections_from(connections, n)
        for s in conns:                 # the strings first: their errors say most
            _check_connection(s)
        if n is not None and len(conns) != n:
            raise ParameterError(f"give one connection string per vehicle ({n} vehicles), "
                                 "or PREFIX:PORT+ for consecutive ports", block="Drones",
                                 param="connections", expected=n, found=conns)
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
        if not prestream > 1.0:
            raise ParameterError("PX4 enables offboard after more than a second of "
                                 "set-points", block="Drones", param="prestream",
                                 expected="> 1 s", found=prestream)
        for nm, v in (("telemetry_rate", telemetry_rate), ("retry_budget", retry_budget),
                      ("loss_timeout_max", loss_timeout_max)):
            if not (np.isfinite(v) and v > 0):
                raise ParameterError("must be a positive number", block="Drones", param=nm,
                                     found=v)
        if ekf_origin is not None:
            e = np.asarray(ekf_origin, float)
            if e.shape != (3,) or not np.isfinite(e).all() or abs(e[0]) > 90 \
                    or abs(e[1]) > 180:
                raise ParameterError("ekf_origin is (latitude, longitude, altitude)",
                                     block="Drones", param="ekf_origin", found=ekf_origin)
            ekf_origin = tuple(float(x) for x in e)
        self.stream_rate, self.hold = float(stream_rate), float(hold)
        self.ack_timeout, self.retries = float(ack_timeout), int(retries)
        self.telemetry_rate, self.prestream = float(telemetry_rate), float(prestream)
        self.retry_budget, self.ekf_origin = float(retry_budget), ekf_origin
        self.allow_unsafe_failsafe = bool(allow_unsafe_failsafe)
        self.loss_timeout_max = float(loss_timeout_max)

    def open_link(self):
        return MavlinkLink(self.names, self.connections, self.origins,
                           stream_rate=self.stream_rate, hold=self.hold,
                           ack_timeout=self.ack_timeout, retries=self.retries,
                           record=self.record, telemetry_rate=self.telemetry_rate,
                           prestream=self.prestream, retry_budget=self.retry_budget,
                           ekf_origin=self.ekf_origin,
                           allow_unsafe_failsafe=self.allow_unsafe_failsafe,
                           loss_timeout_max=self.loss_timeout_max, wait=self.wait)
