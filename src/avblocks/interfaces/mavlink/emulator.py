"""Emulated PX4 or ArduPilot multicopters speaking MAVLink, for tests.

One process, N vehicles; vehicle ``i`` has system id ``i + 1`` and is
reached the way its real counterpart's SITL is (:mod:`._links`):

* ``flavor="px4"`` (default link ``udp``): it owns UDP port
  ``vehicle_port + i`` (14580 + i; by default ``base_port + 40``, PX4's
  spacing of the two) and sends to ``base_port + i`` (14540 + i) on
  ``host``, where the commander listens (``udpin:127.0.0.1:14540+``); it
  answers the first peer that talks to it;
* ``flavor="ardupilot"`` (default link ``tcp``): a TCP server on
  ``base_port + 10 i`` (5760 + 10 i, ArduPilot SITL's SERIAL0), reached
  with ``tcp:127.0.0.1:5760+10``; ``link="udp"`` gives it the UDP layout
  above.

Without ``pose0`` the vehicles stand on the floor on a line along x
centred on 0, ``spacing`` (1 m) apart: where the ``drone_formation``
scenario's agents start (its ``start_positions``), so that ``avblocks run
drone_formation --set agents=N --robots mavlink`` finds each vehicle on
its start slot.

Each vehicle is the library's quadrotor model
(:class:`~avblocks.vehicles.Quadrotor` flown by
:class:`~avblocks.vehicles.QuadrotorVelocityControl`, RK4 in steps of at
most ``dt``, keeping up with the wall clock) under a small firmware that
turns the mode into a velocity set-point for that controller. The
firmware copies what PX4 and ArduPilot do on the link, each behaviour
with the upstream file or page it was read from (learned from, not
copied; the numbers are in :mod:`.autopilots`):

**Both**

* modes: OFFBOARD (PX4) / GUIDED (ArduPilot) follow
  ``SET_POSITION_TARGET_LOCAL_NED`` (velocity or position); takeoff;
  LAND (descend at ``land_speed``, disarm on touchdown); RTL (home at the
  current height, then land); HOLD / BRAKE (hold the position);
* every command answered with ``COMMAND_ACK`` (``COMMAND_LONG`` or
  ``COMMAND_INT``): ``DO_SET_MODE``, ``COMPONENT_ARM_DISARM``,
  ``NAV_TAKEOFF``, ``NAV_LAND``, ``NAV_RETURN_TO_LAUNCH``,
  ``SET_MESSAGE_INTERVAL``, ``REQUEST_MESSAGE`` (``AUTOPILOT_VERSION``
  with the parameter encoding in its capabilities); others
  ``UNSUPPORTED``;
* parameters read and written with ``PARAM_REQUEST_READ``,
  ``PARAM_REQUEST_LIST`` and ``PARAM_SET`` (an unknown name gets no
  answer, as ArduPilot's ``GCS_Param.cpp`` does); integers byte-wise on
  PX4, cast to float on ArduPilot (MAVLink parameter protocol);
* arming refused with a ``STATUSTEXT`` below ``arm_battery_min``
  or without a position estimate; telemetry at the message intervals in
  force (``SET_MESSAGE_INTERVAL``: -1 stops, 0 restores the default);
* ``gimbal=True``: a second component of the same system, a gimbal
  (component 154, ``MAV_TYPE_GIMBAL``, ``MAV_AUTOPILOT_INVALID``), sends
  its own HEARTBEAT once a second, just before the autopilot's.

**PX4** (``src/modules/mavlink/mavlink_main.cpp``, onboard mode;
``src/modules/commander/``)

* streams by default what its onboard link streams:
  ``LOCAL_POSITION_NED`` and ``ATTITUDE_QUATERNION`` (at ``rate``),
  ``EXTENDED_SYS_STATE`` and ``SYS_STATUS`` at 5 Hz, ``BATTERY_STATUS``
  at 0.5 Hz, ``HEARTBEAT`` at 1 Hz (``pose_message="odometry"``:
  ``ODOMETRY``, pose in LOCAL_NED, velocity in BODY_FRD, instead of the
  first two); no handler for ``REQUEST_DATA_STREAM``;
* OFFBOARD accepted only when the last set-point is younger than
  ``COM_OF_LOSS_T`` (``HealthAndArmingChecks/checks/offboardCheck.cpp``)
  and the set-points have streamed without a gap of 0.5 s (2 Hz) for more
  than a second (the offboard mode page, v1.16: "PX4 enables offboard
  control only after receiving the signal for more than a second");
  otherwise, and for a refused arming, ``TEMPORARILY_REJECTED``
  (``Commander.cpp``, ``handle_command``: a denied transition is
  answered so);
* offboard loss: no set-point for ``COM_OF_LOSS_T`` in OFFBOARD ->
  ``COM_OBL_RC_ACT`` (``failsafe/failsafe.cpp``,
  ``fromOffboardLossActParam``; the emulated vehicles have no RC, so
  Position/Altitude/Stabilized fall back to Return as
  ``checkModeFallback`` does; Terminate and Disarm stop the motors: the
  vehicle falls); GCS loss: no GCS heartbeat for ``COM_DL_LOSS_T`` ->
  ``NAV_DLL_ACT`` unless landing (``failsafe.cpp``);
* ``NAV_TAKEOFF`` climbs to ``MIS_TAKEOFF_ALT`` above home (a finite
  ``param7`` is an altitude above the emulated home, which is at 0 m
  AMSL) and then holds (the takeoff mode page).

**ArduPilot Copter** (``ArduCopter/``, ``libraries/GCS_MAVLink/``)

* streams nothing but ``HEARTBEAT`` until asked: the ``SRx_`` stream
  rates of Copter default to 0 (``GCS_MAVLink_Parameters.cpp``);
  ``REQUEST_DATA_STREAM`` starts a group (POSITION: ``LOCAL_POSITION_NED``;
  EXTRA1: ``ATTITUDE``; EXTENDED_STATUS: ``SYS_STATUS``; EXTRA3:
  ``BATTERY_STATUS``; ``ATTITUDE_QUATERNION`` and ``EXTENDED_SYS_STATE``
  are in none), ``SET_MESSAGE_INTERVAL`` any single message it knows
  (``DENIED`` for one it does not, with a ``STATUSTEXT``:
  ``GCS_Common.cpp``, ``set_message_interval``);
* ``DO_SET_MODE`` takes ``param2`` as the Copter mode number (4 GUIDED,
  6 RTL, 9 LAND: ``mode.h``) when ``param1`` has the custom-mode flag,
  ``FAILED`` when the mode cannot be entered, ``DENIED`` without the flag
  (``_set_mode_common``); arming refused -> ``FAILED``
  (``handle_command_component_arm_disarm``);
* GUIDED: velocity set-points older than ``GUID_TIMEOUT`` -> stop and
  hover (``Parameters.cpp``: "vehicle will stop"); GCS failsafe: once a
  heartbeat from system ``SYSID_MYGCS`` has been seen, none for
  ``FS_GCS_TIMEOUT`` while armed -> ``FS_GCS_ENABLE``'s action (0: none)
  (``events.cpp``, ``failsafe_gcs_check``);
* ``indoor=True``: no EKF origin (no GPS): no ``LOCAL_POSITION_NED``
  (``send_local_position`` needs the origin), GUIDED and arming refused,
  until ``SET_GPS_GLOBAL_ORIGIN`` arrives (``handle_set_gps_global_origin``).

The fail-safe parameters start configured as docs/drones.md asks
(``COM_OBL_RC_ACT`` from ``offboard_loss_action``, ``COM_OF_LOSS_T`` =
``offboard_timeout``, ``COM_RC_IN_MODE`` 4; ``FS_GCS_ENABLE`` from
``gcs_loss_action``, ``FS_GCS_TIMEOUT`` = ``gcs_timeout``,
``GUID_TIMEOUT`` = ``guided_timeout``), or at the firmware's defaults
with ``factory_defaults=True``; ``params`` sets any of them.

Faults to test against (keyed by system id): ``silent`` (``{sysid: t}``:
the vehicle sends nothing from ``t`` s after its first velocity
set-point, still obeys), ``stale`` (stops sending positions only),
``no_pose`` (never has a position), ``temp_reject`` (``{sysid: n}``: its
first n mode changes and armings are ``TEMPORARILY_REJECTED``, as PX4
answers while its checks do not pass yet), ``in_progress`` (``{sysid:
s}``: mode changes, arming and takeoff are acknowledged ``IN_PROGRESS``
first and finally ``s`` seconds later, the command protocol's long
running commands), ``deny_interval`` (``{sysid: names}``: those
messages are refused by ``SET_MESSAGE_INTERVAL``), ``no_interval``
(system ids without ``SET_MESSAGE_INTERVAL``: ``UNSUPPORTED``).

Simplifications: no RC, no GPS (positions are local), auto-disarm at
touchdown (PX4 waits ``COM_DISARM_LAND``), no wind, no latency.

The log (JSON lines) has every message received, raw (``hex``: the bytes
as they came off the socket, so tests decode them with their own parser),
and the events (mode changes, arming, refusals, offboard loss, landed),
each with the wall clock and the vehicle's state.
"""

from __future__ import annotations

import json
import os
import threading
import time

import numpy as np

from ...core.errors import ParameterError
from ..flight.cli import start_line
from . import autopilots as ap
from . import frames
from ._links import TcpVehiclePort, UdpVehiclePort
from .autopilots import APM_MODES, PX4_MODES, px4_custom_mode  # noqa: F401 (re-exported)

FLAVORS = ("px4", "ardupilot")
ACTIONS = ("land", "hold", "rtl")
LINKS = ("udp", "tcp")

# MAVLink numbers (common.xml); kept under their old names for importers
CMD_DO_SET_MODE, CMD_ARM, CMD_TAKEOFF, CMD_LAND, CMD_RTL = 176, 400, 22, 21, 20
CMD_SET_INTERVAL, CMD_REQUEST_MESSAGE, CMD_REQUEST_CAPS = 511, 512, 520
RESULT_ACCEPTED, RESULT_TEMP_REJECTED, RESULT_DENIED, RESULT_UNSUPPORTED = 0, 1, 2, 3
RESULT_FAILED, RESULT_IN_PROGRESS = 4, 5
LANDED_ON_GROUND, LANDED_IN_AIR, LANDED_TAKEOFF, LANDED_LANDING = 1, 2, 3, 4
G = 9.81

#: what the configured loss actions mean in each autopilot's parameter
PX4_OBL = {"land": 4, "hold": 5, "rtl": 3}
APM_GCS = {"land": 5, "hold": 7, "rtl": 1}
#: the emulated mode a parameter value leads to (see the module docstring)
PX4_OBL_MODE = {0: "rtl", 1: "rtl", 2: "rtl", 3: "rtl", 4: "land", 5: "hold",
                6: "motors_off", 7: "motors_off"}
PX4_DLL_MODE = {1: "hold", 2: "rtl", 3: "land", 5: "motors_off", 6: "motors_off"}
APM_GCS_MODE = {1: "rtl", 2: "rtl", 3: "rtl", 4: "land", 5: "land", 6: "rtl", 7: "hold"}

#: messages each flavour can stream (SET_MESSAGE_INTERVAL)
STREAMABLE = {"px4": {"HEARTBEAT", "SYS_STATUS", "ATTITUDE", "ATTITUDE_QUATERNION",
                      "LOCAL_POSITION_NED", "BATTERY_STATUS", "EXTENDED_SYS_STATE",
                      "ODOMETRY"},
              "ardupilot": {"HEARTBEAT", "SYS_STATUS", "ATTITUDE", "ATTITUDE_QUATERNION",
                            "LOCAL_POSITION_NED", "BATTERY_STATUS", "EXTENDED_SYS_STATE"}}
#: MAV_PROTOCOL_CAPABILITY bits announced in AUTOPILOT_VERSION: COMMAND_INT 8,
#: SET_POSITION_TARGET_LOCAL_NED 128, MAVLINK2 8192, and the parameter
#: encoding (PARAM_ENCODE_BYTEWISE 16 / PARAM_ENCODE_C_CAST 131072)
CAPABILITIES = {"px4": 8 | 128 | 8192 | 16, "ardupilot": 8 | 128 | 8192 | 131072}


def mavutil():
    """pymavlink's ``mavutil`` with MAVLink 2 framing (extra ``[mavlink]``)."""
    os.environ.setdefault("MAVLINK20", "1")
    try:
        from pymavlink import mavutil as m
    except ImportError:  # pragma: no cover - the extra is missing
        from ...core.errors import AvError
        raise AvError("the MAVLink interface needs pymavlink",
                      hint="pip install 'avblocks[mavlink]'") from None
    return m


def _dialect():
    mavutil()
    from pymavlink.dialects.v20 import common
    return common


class _Wire:
    """The file-like object pymavlink's MAVLink encoder writes to."""

    def __init__(self, link, muted):
        self.link, self.muted = link, muted

    def write(self, buf):
        if not self.muted():
            self.link.write(bytes(buf))


def _ids(d, n, what):
    out = {int(k): v for k, v in (d or {}).items()}
    bad = sorted(set(out) - set(range(1, n + 1)))
    if bad:
        raise ParameterError(f"{what} names a system id that is not emulated", param=what,
                             expected=f"1..{n}", found=bad)
    return out


class Emulator:
    """N emulated MAVLink multicopters (see the module docstring)."""

    def __init__(self, n=None, pose0=None, *, flavor="px4", base_port=14540,
                 host="127.0.0.1", dt=0.04, rate=30.0, battery=1.0, drain=0.0005,
                 arm_battery_min=0.2, offboard_timeout=0.5, offboard_loss_action="land",
                 guided_timeout=3.0, gcs_timeout=5.0, gcs_loss_action="land",
                 land_speed=0.7, climb_speed=1.0, speed_max=3.0, origin="world",
                 silent=None, stale=None, no_pose=(), log=None, mass=1.0,
                 pose_message="local", link=None, vehicle_port=None, params=None,
                 factory_defaults=False, gimbal=False, temp_reject=None, in_progress=None,
                 deny_interval=None, no_interval=(), indoor=False, spacing=1.0):
        from ...vehicles import Quadrotor, QuadrotorVelocityControl
        if flavor not in FLAVORS:
            raise ParameterError("unknown autopilot flavor", param="flavor",
                                 expected=list(FLAVORS), found=flavor)
        for nm, a in (("offboard_loss_action", offboard_loss_action),
                      ("gcs_loss_action", gcs_loss_action)):
            if a not in ACTIONS:
                raise ParameterError("unknown fail-safe action", param=nm,
                                     expected=list(ACTIONS), found=a)
        link = link or ("udp" if flavor == "px4" else "tcp")
        if link not in LINKS:
            raise ParameterError("unknown link", param="link", expected=list(LINKS),
                                 found=link)
        if pose0 is None:
            pose0 = start_line(int(n or 1), spacing)
        p0 = np.asarray(pose0, float)
        if p0.ndim != 2 or p0.shape[1] not in (2, 3):
            raise ParameterError("pose0 must be (N, 2) or (N, 3) start positions [m]",
                                 param="pose0", found=p0.shape)
        if p0.shape[1] == 2:
            p0 = np.column_stack([p0, np.zeros(len(p0))])
        self.n = n = len(p0)
        if pose_message not in ("local", "odometry"):
            raise ParameterError("unknown pose message", param="pose_message",
                                 expected=["local", "odometry"], found=pose_message)
        self.pose_message = pose_message
        self.flavor, self.dt, self.rate = flavor, float(dt), float(rate)
        self.link_kind = link
        self.quad = Quadrotor(p0, mass=mass)
        self.ctrl = QuadrotorVelocityControl.for_quadrotor(self.quad)
        self.x = {k: np.array(v, float) for k, v in self.quad.initial_state().items()}
        self.home = p0.copy()
        self.ground = p0[:, 2].copy()
        self.origin = np.zeros((n, 3)) if origin == "world" else p0.copy()
        self.battery = np.broadcast_to(np.asarray(battery, float), (n,)).copy()
        self.drain, self.arm_battery_min = float(drain), float(arm_battery_min)
        self.land_speed, self.climb_speed, self.speed_max = land_speed, climb_speed, speed_max
        self.silent = {k: float(v) for k, v in _ids(silent, n, "silent").items()}
        self.stale = {k: float(v) for k, v in _ids(stale, n, "stale").items()}
        self.no_pose = set(_ids({int(k): 0 for k in no_pose}, n, "no_pose"))
        self.temp_reject = {k: int(v) for k, v in _ids(temp_reject, n, "temp_reject").items()}
        self.in_progress = {k: float(v) for k, v in _ids(in_progress, n,
                                                         "in_progress").items()}
        self.deny_interval = {k: {str(m).upper() for m in v}
                              for k, v in _ids(deny_interval, n, "deny_interval").items()}
        self.no_interval = set(_ids({int(k): 0 for k in no_interval}, n, "no_interval"))
        self.gimbal = bool(gimbal)
        self.origin_set = np.full(n, not (indoor and flavor == "ardupilot"))
        # parameters: the firmware's defaults, then configured, then given
        self.param_table = ap.PX4_PARAMS if flavor == "px4" else ap.APM_PARAMS
        self.params = []
        for i in range(n):
            p = {k: v[1] for k, v in self.param_table.items()}
            p["MAV_SYS_ID" if flavor == "px4" else "SYSID_THISMAV"] = i + 1
            if not factory_defaults:
                if flavor == "px4":
                    p.update(COM_OF_LOSS_T=float(offboard_timeout),
                             COM_OBL_RC_ACT=PX4_OBL[offboard_loss_action], COM_RC_IN_MODE=4)
                else:
                    p.update(FS_GCS_ENABLE=APM_GCS[gcs_loss_action],
                             FS_GCS_TIMEOUT=float(gcs_timeout),
                             GUID_TIMEOUT=float(guided_timeout))
            for k, v in (params or {}).items():
                if k not in self.param_table:
                    raise ParameterError("not a parameter of the emulated autopilot",
                                         param="params", expected=sorted(self.param_table),
                                         found=k)
                p[k] = float(v) if self.param_table[k][0] == ap.PARAM_REAL32 else int(v)
            self.params.append(p)
        self.armed = np.zeros(n, bool)
        self.mode = ["hold" if flavor == "px4" else "stabilize"] * n
        self.landed = np.ones(n, bool)
        self.sp_kind = [None] * n                 # "vel" | "pos"
        self.sp = np.zeros((n, 3))                # ENU world
        self.t_sp = np.full(n, -np.inf)           # emulator time of the last set-point
        self.t_stream0 = np.full(n, np.inf)       # start of the current set-point stream
        self.t_first_vel = np.full(n, np.nan)
        self.t_gcs = np.full(n, -np.inf)          # last heartbeat of the GCS that counts
        self.gcs_failsafe = np.zeros(n, bool)
        self._t_check = 0.0                       # ArduPilot's 3 Hz failsafe check
        self.target = p0.copy()                   # hold / takeoff / rtl target
        self.falling = np.zeros(n, bool)
        self._pending = []                        # (t_due, i, cmd, message)
        self._progress_done = set()               # (sysid, cmd) answered finally
        # message intervals [s] in force (None: not streamed)
        self.intervals = [self._default_intervals() for _ in range(n)]
        self._next = [dict() for _ in range(n)]
        # the links
        self.host = host
        vport = base_port + 40 if vehicle_port is None else int(vehicle_port)
        if link == "udp":
            self.links = [UdpVehiclePort(host, vport + i, base_port + i) for i in range(n)]
            self.ports = [base_port + i for i in range(n)]
            self.vehicle_ports = [vport + i for i in range(n)]
        else:
            self.links = [TcpVehiclePort(host, base_port + 10 * i) for i in range(n)]
            self.ports = self.vehicle_ports = [base_port + 10 * i for i in range(n)]
        d = _dialect()
        self.d = d
        self.mav = []
        self.mav_gimbal = []
        for i in range(n):
            w = _Wire(self.links[i], lambda i=i: self._muted(i))
            self.mav.append(d.MAVLink(w, srcSystem=i + 1, srcComponent=ap.COMP_AUTOPILOT1))
            self.mav_gimbal.append(d.MAVLink(w, srcSystem=i + 1, srcComponent=ap.COMP_GIMBAL))
        self.parsers = [d.MAVLink(None) for _ in range(n)]
        for prs in self.parsers:
            prs.robust_parsing = True
        self._log = open(log, "a", buffering=1) if log else None
        self._lock = threading.Lock()
        #: Events (every log record but the received messages), in order.
        self.events = []
        self._stop = threading.Event()
        self.t0 = time.monotonic()
        #: Wall seconds not integrated (ticks later than 5 dt on a busy machine).
        self.lost = 0.0
        self.write({"ev": "start", "n": n, "flavor": flavor, "link": link,
                    "ports": self.ports, "vehicle_ports": self.vehicle_ports,
                    "pose0": p0.tolist(), "origin": self.origin.tolist(),
                    "params": self.params[0] if n else {}})

    # ------------------------------------------------------------------ helpers
    def _default_intervals(self):
        if self.flavor == "ardupilot":          # SRx_ rates of Copter: 0
            return {"HEARTBEAT": 1.0}
        iv = {"HEARTBEAT": 1.0, "EXTENDED_SYS_STATE": 0.2, "SYS_STATUS": 0.2,
              "BATTERY_STATUS": 2.0}
        if self.pose_message == "odometry":
            iv["ODOMETRY"] = 1.0 / self.rate
        else:
            iv["LOCAL_POSITION_NED"] = iv["ATTITUDE_QUATERNION"] = 1.0 / self.rate
        return iv

    def now(self):
        return time.monotonic() - self.t0

    def write(self, rec):
        """Log ``rec`` (a dict with ``ev``); events other than ``rx`` are
        also kept in :attr:`events`."""
        rec = {"wall": time.time(), "t": round(self.now(), 4), **rec}
        with self._lock:
            if rec["ev"] != "rx":
                self.events.append(rec)
            if self._log is not None:
                self._log.write(json.dumps(rec) + "\n")

    def event(self, i, ev, **kw):
        self.write({"ev": ev, "sysid": i + 1, "mode": self.mode[i],
                    "armed": bool(self.armed[i]),
                    "pos": np.round(self.x["position"][i], 4).tolist(), **kw})

    def _muted(self, i, what="all"):
        t = self.now()
        t1 = self.t_first_vel[i]
        if i + 1 in self.silent and np.isfinite(t1) and t - t1 >= self.silent[i + 1]:
            return True
        if what == "pose":
            if i + 1 in self.no_pose or not self.origin_set[i]:
                return True
            if i + 1 in self.stale and np.isfinite(t1) and t - t1 >= self.stale[i + 1]:
                return True
        return False

    def set_mode(self, i, mode, why=None):
        if self.mode[i] != mode:
            self.mode[i] = mode
            p = self.x["position"][i]
            if mode == "hold":
                self.target[i] = p
            elif mode == "rtl":
                self.target[i] = [self.home[i, 0], self.home[i, 1], p[2]]
            elif mode == "land":
                self.target[i] = [p[0], p[1], self.ground[i]]
            self.event(i, "mode", to=mode, why=why)

    def _motors_off(self, i, why):
        """Terminate / disarm in the air: the vehicle falls (ballistic)."""
        self.armed[i] = False
        self.falling[i] = not self.landed[i]
        self.event(i, "disarmed", why=why)

    def _custom_mode(self, i):
        md = self.mode[i]
        if self.flavor == "px4":
            return px4_custom_mode({"guided": "offboard", "stabilize": "position",
                                    "loiter": "hold"}.get(md, md))
        return APM_MODES.get({"offboard": "guided", "takeoff": "guided"}.get(md, md), 0)

    def _statustext(self, i, text, severity=4):
        self.mav[i].statustext_send(severity, text.encode()[:50])

    # ------------------------------------------------------------------ receive
    def _receive(self, i):
        try:
            data = self.links[i].read()
        except OSError:
            return
        if not data:
            return
        try:
            msgs = self.parsers[i].parse_buffer(data) or []
        except self.d.MAVError:
            return
        for msg in msgs:
            typ = msg.get_type()
            if typ == "BAD_DATA":
                continue
            if self._log is not None:
                self.write({"ev": "rx", "sysid": i + 1, "type": typ,
                            "hex": bytes(msg.get_msgbuf()).hex()})
            try:
                self._dispatch(i, typ, msg)
            except Exception as e:  # noqa: BLE001 - a malformed message must not stop it
                self.event(i, "rx_error", type=typ, error=f"{type(e).__name__}: {e}")

    def _for_me(self, i, msg):
        return (getattr(msg, "target_system", 0) in (0, i + 1)
                and getattr(msg, "target_component", 0) in (0, ap.COMP_AUTOPILOT1))

    def _dispatch(self, i, typ, msg):
        if typ == "HEARTBEAT":
            gcs = (self.params[i]["SYSID_MYGCS"] if self.flavor == "ardupilot"
                   else None)
            if msg.type == ap.TYPE_GCS and (gcs is None or msg.get_srcSystem() == gcs):
                self.t_gcs[i] = self.now()
            return
        if not self._for_me(i, msg):
            return
        if typ == "SET_POSITION_TARGET_LOCAL_NED":
            self._on_setpoint(i, msg)
        elif typ in ("COMMAND_LONG", "COMMAND_INT"):
            self._on_command(i, msg)
        elif typ == "PARAM_REQUEST_READ":
            self._on_param_read(i, msg)
        elif typ == "PARAM_REQUEST_LIST":
            for k, name in enumerate(self.param_table):
                self._send_param(i, name, k)
        elif typ == "PARAM_SET":
            self._on_param_set(i, msg)
        elif typ == "REQUEST_DATA_STREAM" and self.flavor == "ardupilot":
            self._on_request_data_stream(i, msg)
        elif typ == "SET_GPS_GLOBAL_ORIGIN" and self.flavor == "ardupilot":
            if not self.origin_set[i]:
                self.origin_set[i] = True
                self.event(i, "ekf_origin", lat=msg.latitude, lon=msg.longitude,
                           alt_mm=msg.altitude)

    def _on_setpoint(self, i, msg):
        mask = msg.type_mask
        t = self.now()
        if not mask & 0b111:                                   # position used
            self.sp_kind[i] = "pos"
            self.sp[i] = frames.position_to_world([msg.x, msg.y, msg.z], self.origin[i])
        elif not mask & 0b111000:                              # velocity used
            self.sp_kind[i] = "vel"
            self.sp[i] = frames.ned_to_enu([msg.vx, msg.vy, msg.vz])
            if not np.isfinite(self.t_first_vel[i]):
                self.t_first_vel[i] = t
        else:
            return
        if t - self.t_sp[i] > 0.5:           # a new stream (PX4 needs > 2 Hz)
            self.t_stream0[i] = t
        self.t_sp[i] = t

    # ------------------------------------------------------------------ parameters
    def _send_param(self, i, name, index=-1):
        ptype = self.param_table[name][0]
        field = ap.encode_param(self.params[i][name], ptype, self.flavor)
        self.mav[i].param_value_send(name.encode(), field, ptype, len(self.param_table),
                                     index & 0xFFFF)      # -1: 65535 on the wire

    def _param_name(self, raw):
        if isinstance(raw, bytes):
            raw = raw.decode(errors="replace")
        return raw.split("\x00")[0]

    def _on_param_read(self, i, msg):
        if msg.param_index >= 0:
            names = list(self.param_table)
            if msg.param_index < len(names):
                self._send_param(i, names[msg.param_index], msg.param_index)
            return
        name = self._param_name(msg.param_id)
        if name in self.param_table:          # unknown: no answer (GCS_Param.cpp)
            self._send_param(i, name)

    def _on_param_set(self, i, msg):
        name = self._param_name(msg.param_id)
        if name not in self.param_table or not np.isfinite(msg.param_value):
            return
        ptype = self.param_table[name][0]
        value = ap.decode_param(msg.param_value, ptype, self.flavor)
        self.params[i][name] = value
        self.event(i, "param_set", name=name, value=value)
        self._send_param(i, name)

    # ------------------------------------------------------------------ streams
    def _set_interval(self, i, name, interval_us):
        if interval_us == -1:
            self.intervals[i].pop(name, None)
        elif interval_us == 0:
            default = self._default_intervals().get(name)
            if default is None:
                self.intervals[i].pop(name, None)
            else:
                self.intervals[i][name] = default
        else:
            self.intervals[i][name] = max(interval_us, 1000) / 1e6
        self._next[i].pop(name, None)
        self.event(i, "interval", message=name, interval_s=self.intervals[i].get(name))

    def _on_request_data_stream(self, i, msg):
        if msg.start_stop not in (0, 1):
            return
        rate = msg.req_message_rate if msg.start_stop == 1 else 0
        groups = (list(ap.APM_STREAM_GROUPS) if msg.req_stream_id == 0
                  else [msg.req_stream_id])
        for g in groups:
            for name in ap.APM_STREAM_GROUPS.get(g, ()):
                if name not in STREAMABLE["ardupilot"]:
                    continue
                self._set_interval(i, name, int(1e6 / rate) if rate > 0 else -1)
        self.event(i, "data_stream", stream=ap.APM_STREAM_NAMES.get(msg.req_stream_id,
                                                                     msg.req_stream_id),
                   rate=rate)

    # ------------------------------------------------------------------ commands
    def _ack(self, i, cmd, result, text=None):
        if text:
            self._statustext(i, text)
        self.mav[i].command_ack_send(cmd, result)
        self.event(i, "ack", command=cmd, result=result, text=text)

    def _on_command(self, i, msg):
        cmd = msg.command
        sid = i + 1
        if cmd in (CMD_DO_SET_MODE, CMD_ARM, CMD_TAKEOFF) and sid in self.in_progress \
                and (sid, cmd) not in self._progress_done:
            # the command protocol's long-running commands: IN_PROGRESS now,
            # the final result later (and a repeat of it gets IN_PROGRESS too)
            if any(p[1] == i and p[2] == cmd for p in self._pending):
                return self._ack(i, cmd, RESULT_IN_PROGRESS)
            self._ack(i, cmd, RESULT_IN_PROGRESS)
            self._pending.append((self.now() + self.in_progress[sid], i, cmd, msg))
            return
        if cmd in (CMD_DO_SET_MODE, CMD_ARM) and self.temp_reject.get(sid, 0) > 0 \
                and msg.param1 >= 0.5:
            self.temp_reject[sid] -= 1
            return self._ack(i, cmd, RESULT_TEMP_REJECTED,
                             "Command temporarily rejected: checks not ready")
        return self._execute(i, cmd, msg)

    def _execute(self, i, cmd, msg):
        px4 = self.flavor == "px4"
        refused = RESULT_TEMP_REJECTED if px4 else RESULT_FAILED
        p = self.params[i]
        if cmd == CMD_ARM:
            if msg.param1 >= 0.5:
                if self.armed[i]:
                    return self._ack(i, cmd, RESULT_ACCEPTED)
                if self.battery[i] < self.arm_battery_min:
                    return self._ack(i, cmd, refused,
                                     f"Arming denied: battery {100 * self.battery[i]:.0f}% low")
                if i + 1 in self.no_pose or not self.origin_set[i]:
                    return self._ack(i, cmd, refused, "Arming denied: no position estimate")
                if not px4 and self.mode[i] not in ("guided", "loiter", "stabilize"):
                    return self._ack(i, cmd, refused, "Arm: mode not armable")
                if not px4 and self.gcs_failsafe[i]:
                    return self._ack(i, cmd, refused, "Arm: GCS failsafe on")
                self.armed[i] = True
                self.falling[i] = False
                self.event(i, "armed")
                return self._ack(i, cmd, RESULT_ACCEPTED)
            if not self.landed[i] and msg.param2 != 21196:
                return self._ack(i, cmd, refused, "Disarming denied: not landed")
            self.armed[i] = False
            self.event(i, "disarmed")
            return self._ack(i, cmd, RESULT_ACCEPTED)
        if cmd == CMD_DO_SET_MODE:
            if not px4 and not int(msg.param1) & 1:       # no custom-mode flag
                return self._ack(i, cmd, RESULT_DENIED)
            mode = self._mode_from(int(msg.param2), int(msg.param3))
            if mode is None:
                return self._ack(i, cmd, refused if px4 else RESULT_FAILED,
                                 "Unknown mode")
            if mode == "offboard":
                t = self.now()
                recent = t - self.t_sp[i] <= p["COM_OF_LOSS_T"]
                long_enough = t - self.t_stream0[i] > 1.0
                if not (recent and long_enough):
                    return self._ack(i, cmd, RESULT_TEMP_REJECTED,
                                     "Switching to Offboard is currently not available")
            if mode in ("offboard", "guided") and (i + 1 in self.no_pose
                                                   or not self.origin_set[i]):
                return self._ack(i, cmd, refused, "Flight mode change failed: "
                                                  "no position estimate")
            self.set_mode(i, mode, "command")
            return self._ack(i, cmd, RESULT_ACCEPTED)
        if cmd == CMD_TAKEOFF:
            if not self.armed[i]:
                return self._ack(i, cmd, refused, "Takeoff denied: disarmed")
            if not px4 and self.mode[i] != "guided":
                return self._ack(i, cmd, RESULT_FAILED, "Takeoff: not in GUIDED")
            pos = self.x["position"][i]
            if px4:
                h = p["MIS_TAKEOFF_ALT"] if not np.isfinite(msg.param7) else \
                    float(msg.param7) - self.home[i, 2]
            else:
                h = float(msg.param7)
            self.target[i] = [pos[0], pos[1], self.ground[i] + max(h, 0.5)]
            self.mode[i] = "takeoff"
            self.landed[i] = False
            self.event(i, "mode", to="takeoff", height=h)
            return self._ack(i, cmd, RESULT_ACCEPTED)
        if cmd in (CMD_LAND, CMD_RTL):
            self.set_mode(i, "land" if cmd == CMD_LAND else "rtl", "command")
            return self._ack(i, cmd, RESULT_ACCEPTED)
        if cmd == CMD_SET_INTERVAL:
            name = ap.MSG_NAME.get(int(msg.param1), str(int(msg.param1)))
            if i + 1 in self.no_interval:
                return self._ack(i, cmd, RESULT_UNSUPPORTED)
            if not px4 and msg.param3 != 0:
                return self._ack(i, cmd, RESULT_DENIED)
            if name not in STREAMABLE[self.flavor] or \
                    name in self.deny_interval.get(i + 1, ()):
                return self._ack(i, cmd, RESULT_DENIED,
                                 f"No ap_message for mavlink id ({int(msg.param1)})")
            interval = int(msg.param2)
            if interval < -1:
                return self._ack(i, cmd, RESULT_DENIED)
            self._set_interval(i, name, interval)
            return self._ack(i, cmd, RESULT_ACCEPTED)
        if cmd in (CMD_REQUEST_MESSAGE, CMD_REQUEST_CAPS):
            mid = 148 if cmd == CMD_REQUEST_CAPS else int(msg.param1)
            name = ap.MSG_NAME.get(mid)
            if name == "AUTOPILOT_VERSION":
                self._send_version(i)
            elif name in STREAMABLE[self.flavor]:
                self._send_message(i, name, self.now())
            else:
                return self._ack(i, cmd, RESULT_FAILED)
            return self._ack(i, cmd, RESULT_ACCEPTED)
        return self._ack(i, cmd, RESULT_UNSUPPORTED)

    def _run_pending(self):
        t = self.now()
        due = [p for p in self._pending if p[0] <= t]
        if not due:
            return
        self._pending = [p for p in self._pending if p[0] > t]
        for _, i, cmd, msg in due:
            self._progress_done.add((i + 1, cmd))
            self._execute(i, cmd, msg)

    def _mode_from(self, main, sub):
        if self.flavor == "px4":
            for name, (mm, ss) in PX4_MODES.items():
                if mm == main and (ss == sub or mm != 4):
                    return "hold" if name == "position" else name
            return None
        for name, num in APM_MODES.items():
            if num == main:
                return name
        return None

    # ------------------------------------------------------------------ firmware
    def _px4_failsafes(self, i, t):
        """PX4's offboard loss and data link loss (failsafe.cpp), armed."""
        p = self.params[i]
        md = self.mode[i]
        if md == "offboard" and t - self.t_sp[i] > p["COM_OF_LOSS_T"]:
            to = PX4_OBL_MODE.get(int(p["COM_OBL_RC_ACT"]), "rtl")
            self.event(i, "offboard_loss", last_setpoint=float(self.t_sp[i]), action=to)
            if to == "motors_off":
                self._motors_off(i, "offboard loss (COM_OBL_RC_ACT)")
            else:
                self.set_mode(i, to, "offboard loss")
        dll = int(p["NAV_DLL_ACT"])
        lost = np.isfinite(self.t_gcs[i]) and t - self.t_gcs[i] > p["COM_DL_LOSS_T"]
        if not lost:
            self.gcs_failsafe[i] = False
        elif dll and md != "land" and not self.gcs_failsafe[i]:
            self.gcs_failsafe[i] = True
            to = PX4_DLL_MODE.get(dll, "hold")
            self.event(i, "gcs_loss", last_heartbeat=float(self.t_gcs[i]), action=to)
            if to == "motors_off":
                self._motors_off(i, "data link loss (NAV_DLL_ACT)")
            else:
                self.set_mode(i, to, "data link loss")

    def _apm_gcs_check(self, i, t):
        """ArduCopter's failsafe_gcs_check (events.cpp), run at 3 Hz armed or
        not (three_hz_loop): once a heartbeat of SYSID_MYGCS was seen, none
        for FS_GCS_TIMEOUT sets the failsafe (which refuses arming, "GCS
        failsafe on", AP_Arming_Copter.cpp) and, armed, starts its action;
        the next check after a heartbeat clears it."""
        p = self.params[i]
        fs = int(p["FS_GCS_ENABLE"])
        if not fs or not np.isfinite(self.t_gcs[i]):
            return
        lost = t - self.t_gcs[i] > p["FS_GCS_TIMEOUT"]
        if not lost and self.gcs_failsafe[i]:
            self.gcs_failsafe[i] = False
            self._statustext(i, "GCS Failsafe Cleared", 6)
            self.event(i, "gcs_failsafe_cleared")
        elif lost and not self.gcs_failsafe[i]:
            self.gcs_failsafe[i] = True
            to = APM_GCS_MODE.get(fs, "rtl") if self.armed[i] else None
            self._statustext(i, "Failsafe: GCS", 2)
            self.event(i, "gcs_loss", last_heartbeat=float(self.t_gcs[i]), action=to)
            if to is not None and self.mode[i] != "land":
                self.set_mode(i, to, "GCS heartbeat loss")

    def _vref(self, t):
        """The velocity set-point (N, 3) for the velocity controller."""
        p = self.x["position"]
        v = np.zeros((self.n, 3))
        for i in range(self.n):
            if not self.armed[i]:
                continue
            if self.flavor == "px4":
                self._px4_failsafes(i, t)
            md = self.mode[i]
            if not self.armed[i]:
                continue
            if md in ("offboard", "guided"):
                if self.sp_kind[i] == "vel":
                    if md == "guided" and t - self.t_sp[i] > self.params[i]["GUID_TIMEOUT"]:
                        v[i] = 0.0
                    else:
                        v[i] = self.sp[i]
                elif self.sp_kind[i] == "pos":
                    v[i] = self._goto(p[i], self.sp[i], self.speed_max)
                else:                       # no set-point yet: hold (after a takeoff)
                    v[i] = self._goto(p[i], self.target[i], self.climb_speed)
            elif md in ("hold", "loiter", "stabilize", "takeoff"):
                v[i] = self._goto(p[i], self.target[i], self.climb_speed)
                if md == "takeoff" and abs(p[i, 2] - self.target[i, 2]) < 0.05 \
                        and abs(self.x["velocity"][i, 2]) < 0.1:
                    # PX4: takeoff, then Hold; ArduPilot: stays in GUIDED
                    self.set_mode(i, "hold" if self.flavor == "px4" else "guided",
                                  "takeoff done")
                    if self.flavor != "px4":
                        self.sp_kind[i] = None
            elif md == "rtl":
                d = self.target[i] - p[i]
                if np.hypot(d[0], d[1]) < 0.1:
                    self.set_mode(i, "land", "home reached")
                v[i] = self._goto(p[i], self.target[i], self.climb_speed)
            if self.mode[i] == "land":
                v[i, :2] = self._goto(p[i], self.target[i], 0.5)[:2]
                v[i, 2] = -self.land_speed
        return v

    @staticmethod
    def _goto(p, target, vmax, gain=1.5):
        v = gain * (np.asarray(target) - p)
        s = np.linalg.norm(v)
        return v * min(1.0, vmax / max(s, 1e-12))

    def _rhs(self, x, vref):
        out = self.quad.output(0.0, x, {}, np)
        w = self.ctrl.output(0.0, {}, {"velocity": vref, "measured_velocity": out["velocity"],
                                       "attitude": out["attitude"], "rates": x["rates"]},
                             np)["wrench"]
        return self.quad.derivative(0.0, x, {"wrench": w}, np)

    def _step(self, vref, h):
        """One RK4 step of the armed, flying vehicles; the others stay put
        (or fall, with their motors off)."""
        x = self.x
        k1 = self._rhs(x, vref)
        k2 = self._rhs({k: x[k] + h / 2 * k1[k] for k in x}, vref)
        k3 = self._rhs({k: x[k] + h / 2 * k2[k] for k in x}, vref)
        k4 = self._rhs({k: x[k] + h * k3[k] for k in x}, vref)
        new = {k: x[k] + h / 6 * (k1[k] + 2 * k2[k] + 2 * k3[k] + k4[k]) for k in x}
        on_ground = x["position"][:, 2] - self.ground < 0.02
        fly = self.armed & ~(on_ground & (vref[:, 2] <= 0.0))
        for k in x:
            new[k] = np.where(fly[:, None], new[k], x[k])
        if self.falling.any():                  # motors off in the air: free fall
            f = self.falling
            new["velocity"][f, 2] = x["velocity"][f, 2] - G * h
            new["position"][f] = x["position"][f] + h * x["velocity"][f]
        # the ground: no vehicle goes below it
        below = new["position"][:, 2] < self.ground
        if below.any():
            for i in np.nonzero(below & self.falling)[0]:
                self.falling[i] = False
                self.landed[i] = True
                self.event(i, "crashed", impact_speed=float(-new["velocity"][i, 2]))
            new["position"][below, 2] = self.ground[below]
            new["velocity"][below] = 0.0
            new["rates"][below] = 0.0
        self.x = new
        t = self.now()
        for i in range(self.n):
            z = new["position"][i, 2] - self.ground[i]
            if self.armed[i] and self.landed[i] and z > 0.05:
                self.landed[i] = False
                self.event(i, "airborne")
            if self.armed[i] and self.mode[i] == "land" and z < 0.02:   # (or never left)
                self.landed[i] = True
                self.armed[i] = False
                self.x["velocity"][i] = 0.0
                self.x["rates"][i] = 0.0
                self.event(i, "landed", t_landed=t)
                self.event(i, "disarmed", why="auto-disarm after landing")
        self.battery = np.maximum(self.battery - self.drain * h * self.armed, 0.0)

    # ------------------------------------------------------------------ send
    def _send_version(self, i):
        sw = (1 << 24) | (15 << 16) if self.flavor == "px4" else (4 << 24) | (6 << 16)
        self.mav[i].autopilot_version_send(CAPABILITIES[self.flavor], sw, 0, 0, 0,
                                           [0] * 8, [0] * 8, [0] * 8, 0, 0, i + 1)

    def _send_message(self, i, name, t):
        mav = self.mav[i]
        ms = int(t * 1000) & 0xFFFFFFFF
        if name == "HEARTBEAT":
            if self.gimbal:           # the second component first: the naive pick
                self.mav_gimbal[i].heartbeat_send(ap.TYPE_GIMBAL, ap.AUTOPILOT_INVALID,
                                                  0, 0, 4)
            apt = ap.AUTOPILOT_PX4 if self.flavor == "px4" else ap.AUTOPILOT_ARDUPILOTMEGA
            base = 1 | (128 if self.armed[i] else 0)
            mav.heartbeat_send(2, apt, base, self._custom_mode(i), 4 if self.armed[i] else 3)
            return
        if name == "EXTENDED_SYS_STATE":
            ls = (LANDED_ON_GROUND if self.landed[i] else LANDED_LANDING
                  if self.mode[i] == "land" else LANDED_TAKEOFF if self.mode[i] == "takeoff"
                  else LANDED_IN_AIR)
            mav.extended_sys_state_send(0, ls)
            return
        if name in ("SYS_STATUS", "BATTERY_STATUS"):
            pct = int(round(100 * self.battery[i]))
            mv = int(1000 * (13.2 + 3.6 * self.battery[i]))
            if name == "SYS_STATUS":
                mav.sys_status_send(0, 0, 0, 500, mv, -1, pct, 0, 0, 0, 0, 0, 0)
            else:
                mav.battery_status_send(0, 0, 1, 2500, [mv] + [65535] * 9, -1, -1, -1, pct)
            return
        if self._muted(i, "pose"):
            return
        p = frames.position_to_local(self.x["position"][i], self.origin[i])
        v = frames.enu_to_ned(self.x["velocity"][i])
        q = frames.quat_to_ned(self.quad.output(0.0, self.x, {}, np)["attitude"][i])
        w_frd = self.x["rates"][i] * [1.0, -1.0, -1.0]      # body FLU -> FRD
        if name == "LOCAL_POSITION_NED":
            mav.local_position_ned_send(ms, *p, *v)
        elif name == "ATTITUDE_QUATERNION":
            mav.attitude_quaternion_send(ms, *q, *w_frd)
        elif name == "ATTITUDE":
            w, x, y, z = q
            roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
            pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1, 1))
            yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
            mav.attitude_send(ms, roll, pitch, yaw, *w_frd)
        elif name == "ODOMETRY":
            # as PX4 sends it: pose in LOCAL_NED, velocity in BODY_FRD
            v_body = _rotmat(q).T @ v
            nan21 = [float("nan")] + [0.0] * 20
            mav.odometry_send(ms * 1000, 1, 12, *p, list(q), *v_body, *w_frd, nan21, nan21)

    def _send_due(self, i, t):
        if self._muted(i):
            return
        nxt = self._next[i]
        for name, iv in list(self.intervals[i].items()):
            due = nxt.get(name, -np.inf)
            if t + 1e-4 >= due:
                self._send_message(i, name, t)
                nxt[name] = max(due + iv, t + 0.5 * iv) if np.isfinite(due) else t + iv

    def run(self, duration=None):
        """Run until :meth:`stop` or ``duration`` seconds. Each tick integrates
        the wall time elapsed since the last one (in up to 5 RK4 steps of at
        most ``dt``), so the vehicles keep real time on a loaded machine."""
        end = None if duration is None else time.monotonic() + duration
        t_prev = self.now()
        tick = min(self.dt, 1.0 / self.rate)
        while not self._stop.is_set() and (end is None or time.monotonic() < end):
            for i in range(self.n):
                self._receive(i)
            self._run_pending()
            t = self.now()
            if self.flavor == "ardupilot" and t >= self._t_check:
                self._t_check = t + 1.0 / 3.0
                for i in range(self.n):
                    self._apm_gcs_check(i, t)
            el = min(t - t_prev, 5 * self.dt)
            self.lost += max(t - t_prev - el, 0.0)
            t_prev = t
            vref = self._vref(t)
            nsub = max(1, int(np.ceil(el / self.dt - 1e-9)))
            for _ in range(nsub):
                self._step(vref, el / nsub)
            for i in range(self.n):
                self._send_due(i, t)
            lag = t + tick - self.now()
            if lag > 0:
                time.sleep(lag)
        self.write({"ev": "end", "lost_s": round(self.lost, 3),
                    "positions": self.x["position"].tolist(),
                    "armed": self.armed.tolist(), "landed": self.landed.tolist(),
                    "modes": list(self.mode)})

    def stop(self):
        self._stop.set()

    def close(self):
        for c in self.links:
            c.close()
        if self._log is not None:
            self._log.close()
            self._log = None


def _rotmat(q):
    """Rotation matrix of a unit quaternion (w, x, y, z)."""
    w, x, y, z = np.asarray(q, float) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def read_log(path):
    """The emulator's JSON-lines log as a list of dicts."""
    with open(path) as f:
        return [json.loads(line) for line in f if line.strip()]
