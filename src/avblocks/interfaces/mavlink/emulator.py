"""Emulated PX4 or ArduPilot multicopters speaking MAVLink on UDP.

One process, N vehicles; vehicle ``i`` has system id ``i + 1`` and listens
on ``udpin:127.0.0.1:<base_port + i>`` (it answers whoever talks to it,
as PX4 SITL does on its offboard port). Each vehicle is the library's
quadrotor model (:class:`~avblocks.vehicles.Quadrotor` flown by
:class:`~avblocks.vehicles.QuadrotorVelocityControl`, integrated with RK4
in steps of at most ``dt`` (40 ms) to keep up with the wall clock) under a
small "firmware" that turns the mode into a velocity set-point for that
controller:

* **modes** (PX4 main/sub modes, ArduCopter mode numbers): OFFBOARD /
  GUIDED (set-points from ``SET_POSITION_TARGET_LOCAL_NED``: velocity or
  position), AUTO.TAKEOFF (ArduPilot: ``MAV_CMD_NAV_TAKEOFF`` in GUIDED),
  AUTO.LAND / LAND (descend at ``land_speed``; on the ground: landed,
  disarmed), AUTO.RTL / RTL (fly home at the current height, then land),
  AUTO.LOITER / BRAKE (hold the position);
* **commands**, each answered with ``COMMAND_ACK``: ``DO_SET_MODE`` (176),
  ``COMPONENT_ARM_DISARM`` (400), ``NAV_TAKEOFF`` (22), ``NAV_LAND`` (21),
  ``NAV_RETURN_TO_LAUNCH`` (20); others ``UNSUPPORTED``;
* **arming checks**: refused (``MAV_RESULT_DENIED`` and a ``STATUSTEXT``
  with the reason) with a battery below ``arm_battery_min``, without a
  position estimate (``no_pose``), or (PX4) OFFBOARD refused unless
  set-points arrived in the last ``offboard_timeout``;
* **offboard loss**: PX4, no set-point for ``offboard_timeout`` [s] in
  OFFBOARD (``COM_OF_LOSS_T``) -> ``offboard_loss_action`` (``land``,
  ``hold`` or ``rtl``; ``COM_OBL_RC_ACT``); ArduPilot, no set-point for
  ``guided_timeout`` in GUIDED -> stop and hold, and no GCS heartbeat for
  ``gcs_timeout`` while armed -> ``gcs_loss_action`` (``FS_GCS_ENABLE``);
* **telemetry**: ``HEARTBEAT`` (1 Hz), ``LOCAL_POSITION_NED`` and
  ``ATTITUDE_QUATERNION`` (``rate`` Hz, 30 by default, NED/FRD through
  :mod:`.frames`; or ``ODOMETRY`` with ``pose_message="odometry"``, pose
  in LOCAL_NED and velocity in BODY_FRD as PX4 sends it),
  ``EXTENDED_SYS_STATE`` (landed state), ``SYS_STATUS`` and
  ``BATTERY_STATUS`` (2 Hz; the charge drains at ``drain`` per armed
  second).

Faults to test against (keyed by system id): ``silent`` (``{sysid: t}``:
the vehicle sends nothing from ``t`` s after its first velocity set-point,
still obeys), ``stale`` (stops sending positions only), ``no_pose``
(never sends a position).

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
from .._emulator import run_emulator
from . import frames

FLAVORS = ("px4", "ardupilot")
ACTIONS = ("land", "hold", "rtl")

# MAVLink numbers (common.xml)
CMD_DO_SET_MODE, CMD_ARM, CMD_TAKEOFF, CMD_LAND, CMD_RTL = 176, 400, 22, 21, 20
RESULT_ACCEPTED, RESULT_TEMP_REJECTED, RESULT_DENIED, RESULT_UNSUPPORTED = 0, 1, 2, 3
RESULT_FAILED = 4
LANDED_ON_GROUND, LANDED_IN_AIR, LANDED_TAKEOFF, LANDED_LANDING = 1, 2, 3, 4
#: PX4 custom mode = main << 16 | sub << 24 (px4_custom_mode.h)
PX4_MODES = {"offboard": (6, 0), "takeoff": (4, 2), "hold": (4, 3), "rtl": (4, 5),
             "land": (4, 6), "position": (3, 0)}
#: ArduCopter mode numbers (mode.h)
APM_MODES = {"guided": 4, "hold": 17, "rtl": 6, "land": 9, "loiter": 5, "stabilize": 0}


def px4_custom_mode(name):
    main, sub = PX4_MODES[name]
    return (main << 16) | (sub << 24)


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


class Emulator:
    """N emulated MAVLink multicopters (see the module docstring)."""

    def __init__(self, n=None, pose0=None, *, flavor="px4", base_port=14540,
                 host="127.0.0.1", dt=0.04, rate=30.0, battery=1.0, drain=0.0005,
                 arm_battery_min=0.2, offboard_timeout=0.5, offboard_loss_action="land",
                 guided_timeout=3.0, gcs_timeout=5.0, gcs_loss_action="land",
                 land_speed=0.7, climb_speed=1.0, speed_max=3.0, origin="world",
                 silent=None, stale=None, no_pose=(), log=None, mass=1.0,
                 pose_message="local"):
        from ...vehicles import Quadrotor, QuadrotorVelocityControl
        if flavor not in FLAVORS:
            raise ParameterError("unknown autopilot flavor", param="flavor",
                                 expected=list(FLAVORS), found=flavor)
        for nm, a in (("offboard_loss_action", offboard_loss_action),
                      ("gcs_loss_action", gcs_loss_action)):
            if a not in ACTIONS:
                raise ParameterError("unknown fail-safe action", param=nm,
                                     expected=list(ACTIONS), found=a)
        if pose0 is None:
            n = int(n or 1)
            pose0 = [[1.0 * k, 0.0, 0.0] for k in range(n)]
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
        self.quad = Quadrotor(p0, mass=mass)
        self.ctrl = QuadrotorVelocityControl.for_quadrotor(self.quad)
        self.x = {k: np.array(v, float) for k, v in self.quad.initial_state().items()}
        self.home = p0.copy()
        self.ground = p0[:, 2].copy()
        self.origin = np.zeros((n, 3)) if origin == "world" else p0.copy()
        self.battery = np.broadcast_to(np.asarray(battery, float), (n,)).copy()
        self.drain, self.arm_battery_min = float(drain), float(arm_battery_min)
        self.offboard_timeout, self.offboard_loss_action = offboard_timeout, offboard_loss_action
        self.guided_timeout, self.gcs_timeout = guided_timeout, gcs_timeout
        self.gcs_loss_action = gcs_loss_action
        self.land_speed, self.climb_speed, self.speed_max = land_speed, climb_speed, speed_max
        self.silent = {int(k): float(v) for k, v in (silent or {}).items()}
        self.stale = {int(k): float(v) for k, v in (stale or {}).items()}
        self.no_pose = {int(k) for k in no_pose}
        for what, ids in (("silent", self.silent), ("stale", self.stale),
                          ("no_pose", self.no_pose)):
            bad = sorted(set(ids) - set(range(1, n + 1)))
            if bad:
                raise ParameterError(f"{what} names a system id that is not emulated",
                                     param=what, expected=f"1..{n}", found=bad)
        self.armed = np.zeros(n, bool)
        self.mode = ["hold" if flavor == "px4" else "stabilize"] * n
        self.landed = np.ones(n, bool)
        self.sp_kind = [None] * n                 # "vel" | "pos"
        self.sp = np.zeros((n, 3))                # ENU world
        self.t_sp = np.full(n, -np.inf)           # emulator time of the last set-point
        self.t_first_vel = np.full(n, np.nan)
        self.t_gcs = np.full(n, -np.inf)
        self.target = p0.copy()                   # hold / takeoff / rtl target
        self.landed_state = np.full(n, LANDED_ON_GROUND)
        m = mavutil()
        self.m = m
        self.conns = [m.mavlink_connection(f"udpin:{host}:{base_port + i}",
                                           source_system=i + 1, source_component=1)
                      for i in range(n)]
        self.ports = [base_port + i for i in range(n)]
        self._log = open(log, "a", buffering=1) if log else None
        self._lock = threading.Lock()
        #: Events (every log record but the received messages), in order.
        self.events = []
        self._stop = threading.Event()
        self.t0 = time.monotonic()
        #: Wall seconds not integrated (ticks later than 5 dt on a busy machine).
        self.lost = 0.0
        self.write({"ev": "start", "n": n, "flavor": flavor, "ports": self.ports,
                    "pose0": p0.tolist(), "origin": self.origin.tolist()})

    # ------------------------------------------------------------------ helpers
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
            if i + 1 in self.no_pose:
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

    def _custom_mode(self, i):
        md = self.mode[i]
        if self.flavor == "px4":
            return px4_custom_mode({"guided": "offboard", "stabilize": "position",
                                    "loiter": "hold"}.get(md, md))
        return APM_MODES.get({"offboard": "guided", "takeoff": "guided"}.get(md, md), 0)

    def _statustext(self, i, text, severity=4):
        if not self._muted(i):
            self.conns[i].mav.statustext_send(severity, text.encode()[:50])

    # ------------------------------------------------------------------ receive
    def _receive(self, i):
        c = self.conns[i]
        while True:
            try:
                msg = c.recv_msg()
            except (OSError, self.m.mavlink.MAVError):
                return
            if msg is None:
                return
            typ = msg.get_type()
            if typ == "BAD_DATA":
                continue
            if self._log is not None:
                self.write({"ev": "rx", "sysid": i + 1, "type": typ,
                            "hex": bytes(msg.get_msgbuf()).hex()})
            if typ == "HEARTBEAT":
                self.t_gcs[i] = self.now()
            elif typ == "SET_POSITION_TARGET_LOCAL_NED":
                self._on_setpoint(i, msg)
            elif typ == "COMMAND_LONG":
                self._on_command(i, msg)

    def _on_setpoint(self, i, msg):
        if msg.target_system not in (0, i + 1):
            return
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
        self.t_sp[i] = t

    def _ack(self, i, cmd, result, text=None):
        if text:
            self._statustext(i, text)
        if not self._muted(i):
            self.conns[i].mav.command_ack_send(cmd, result)
        self.event(i, "ack", command=cmd, result=result, text=text)

    def _on_command(self, i, msg):
        if msg.target_system not in (0, i + 1):
            return
        cmd = msg.command
        px4 = self.flavor == "px4"
        if cmd == CMD_ARM:
            if msg.param1 >= 0.5:
                if self.armed[i]:
                    return self._ack(i, cmd, RESULT_ACCEPTED)
                if self.battery[i] < self.arm_battery_min:
                    return self._ack(i, cmd, RESULT_DENIED,
                                     f"Arming denied: battery {100 * self.battery[i]:.0f}% low")
                if i + 1 in self.no_pose:
                    return self._ack(i, cmd, RESULT_DENIED,
                                     "Arming denied: no position estimate")
                if not px4 and self.mode[i] not in ("guided", "loiter", "stabilize"):
                    return self._ack(i, cmd, RESULT_DENIED, "Arm: mode not armable")
                self.armed[i] = True
                self.event(i, "armed")
                return self._ack(i, cmd, RESULT_ACCEPTED)
            if not self.landed[i] and msg.param2 != 21196:
                return self._ack(i, cmd, RESULT_DENIED, "Disarming denied: not landed")
            self.armed[i] = False
            self.event(i, "disarmed")
            return self._ack(i, cmd, RESULT_ACCEPTED)
        if cmd == CMD_DO_SET_MODE:
            mode = self._mode_from(int(msg.param2), int(msg.param3))
            if mode is None:
                return self._ack(i, cmd, RESULT_UNSUPPORTED, "Unknown mode")
            if mode == "offboard" and self.now() - self.t_sp[i] > self.offboard_timeout:
                return self._ack(i, cmd, RESULT_TEMP_REJECTED,
                                 "Switching to Offboard is currently not available")
            if mode in ("offboard", "guided") and i + 1 in self.no_pose:
                return self._ack(i, cmd, RESULT_DENIED, "No valid position estimate")
            self.set_mode(i, mode, "command")
            return self._ack(i, cmd, RESULT_ACCEPTED)
        if cmd == CMD_TAKEOFF:
            if not self.armed[i]:
                return self._ack(i, cmd, RESULT_DENIED, "Takeoff denied: disarmed")
            if not px4 and self.mode[i] != "guided":
                return self._ack(i, cmd, RESULT_DENIED, "Takeoff: not in GUIDED")
            p = self.x["position"][i]
            h = msg.param7 if not px4 else 2.5
            self.target[i] = [p[0], p[1], self.ground[i] + h]
            self.mode[i] = "takeoff"
            self.landed[i] = False
            self.event(i, "mode", to="takeoff", height=h)
            return self._ack(i, cmd, RESULT_ACCEPTED)
        if cmd in (CMD_LAND, CMD_RTL):
            self.set_mode(i, "land" if cmd == CMD_LAND else "rtl", "command")
            return self._ack(i, cmd, RESULT_ACCEPTED)
        return self._ack(i, cmd, RESULT_UNSUPPORTED)

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
    def _vref(self, t):
        """The velocity set-point (N, 3) for the velocity controller."""
        p = self.x["position"]
        v = np.zeros((self.n, 3))
        for i in range(self.n):
            md = self.mode[i]
            if not self.armed[i]:
                continue
            # set-point timeouts
            if md == "offboard" and t - self.t_sp[i] > self.offboard_timeout:
                self.set_mode(i, self.offboard_loss_action, "offboard loss")
                self.event(i, "offboard_loss", last_setpoint=float(self.t_sp[i]))
                md = self.mode[i]
            if self.flavor == "ardupilot" and t - self.t_gcs[i] > self.gcs_timeout \
                    and md not in ("land", "rtl"):
                self.set_mode(i, self.gcs_loss_action, "GCS heartbeat loss")
                self.event(i, "gcs_loss", last_heartbeat=float(self.t_gcs[i]))
                md = self.mode[i]
            if md in ("offboard", "guided"):
                if self.sp_kind[i] == "vel":
                    if md == "guided" and t - self.t_sp[i] > self.guided_timeout:
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
                    self.set_mode(i, "guided", "takeoff done")
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
        """One RK4 step of the armed, flying vehicles; the others stay put."""
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
        # the ground: no vehicle goes below it
        below = new["position"][:, 2] < self.ground
        if below.any():
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
    def _send_telemetry(self, i, t, slow, hb):
        if self._muted(i):
            return
        mav = self.conns[i].mav
        ms = int(t * 1000) & 0xFFFFFFFF
        if hb:
            ap = (self.m.mavlink.MAV_AUTOPILOT_PX4 if self.flavor == "px4"
                  else self.m.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA)
            base = 1 | (128 if self.armed[i] else 0)
            mav.heartbeat_send(2, ap, base, self._custom_mode(i),
                               4 if self.armed[i] else 3)
        if not self._muted(i, "pose"):
            p = frames.position_to_local(self.x["position"][i], self.origin[i])
            v = frames.enu_to_ned(self.x["velocity"][i])
            q = frames.quat_to_ned(self.quad.output(0.0, self.x, {}, np)["attitude"][i])
            w_frd = self.x["rates"][i] * [1.0, -1.0, -1.0]      # body FLU -> FRD
            if self.pose_message == "odometry":
                # as PX4 sends it: pose in LOCAL_NED, velocity in BODY_FRD
                v_body = _rotmat(q).T @ v
                nan21 = [float("nan")] + [0.0] * 20
                mav.odometry_send(ms * 1000, 1, 12, *p, list(q), *v_body, *w_frd, nan21,
                                  nan21)
            else:
                mav.local_position_ned_send(ms, *p, *v)
                mav.attitude_quaternion_send(ms, *q, *w_frd)
        ls = (LANDED_ON_GROUND if self.landed[i] else LANDED_LANDING
              if self.mode[i] == "land" else LANDED_IN_AIR)
        mav.extended_sys_state_send(0, ls)
        if slow:
            pct = int(round(100 * self.battery[i]))
            mv = int(1000 * (13.2 + 3.6 * self.battery[i]))
            mav.sys_status_send(0, 0, 0, 500, mv, -1, pct, 0, 0, 0, 0, 0, 0)
            mav.battery_status_send(0, 0, 1, 2500, [mv] + [65535] * 9, -1, -1, -1, pct)

    def run(self, duration=None):
        """Run until :meth:`stop` or ``duration`` seconds. Each tick integrates
        the wall time elapsed since the last one (in up to 5 RK4 steps of at
        most ``dt``), so the vehicles keep real time on a loaded machine."""
        end = None if duration is None else time.monotonic() + duration
        t_prev = self.now()
        t_tel = t_slow = t_hb = -np.inf
        while not self._stop.is_set() and (end is None or time.monotonic() < end):
            for i in range(self.n):
                self._receive(i)
            t = self.now()
            el = min(t - t_prev, 5 * self.dt)
            self.lost += max(t - t_prev - el, 0.0)
            t_prev = t
            vref = self._vref(t)
            nsub = max(1, int(np.ceil(el / self.dt - 1e-9)))
            for _ in range(nsub):
                self._step(vref, el / nsub)
            if t - t_tel >= 1.0 / self.rate - 1e-4:
                t_tel = t
                slow, hb = t - t_slow >= 0.5, t - t_hb >= 1.0
                t_slow = t if slow else t_slow
                t_hb = t if hb else t_hb
                for i in range(self.n):
                    self._send_telemetry(i, t, slow, hb)
            lag = t + self.dt - self.now()
            if lag > 0:
                time.sleep(lag)
        self.write({"ev": "end", "lost_s": round(self.lost, 3),
                    "positions": self.x["position"].tolist(),
                    "armed": self.armed.tolist(), "landed": self.landed.tolist(),
                    "modes": list(self.mode)})

    def stop(self):
        self._stop.set()

    def close(self):
        for c in self.conns:
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


def _parse_faults(items):
    """``["2@1.5s", "3@0"]`` -> ``{2: 1.5, 3: 0.0}`` (system id @ seconds)."""
    out = {}
    for it in items or []:
        for part in str(it).split(","):
            if not part.strip():
                continue
            try:
                sid, t = part.split("@", 1)
                out[int(sid)] = float(t.strip().rstrip("s"))
            except ValueError:
                raise ParameterError("a fault is SYSID@SECONDS, e.g. 2@1.5s",
                                     found=part) from None
    return out


def main(args):
    """``avblocks mavlink emulate``."""
    pose0 = json.loads(args.pose0) if args.pose0 else None
    if pose0 is None:
        pose0 = [[args.spacing * k, 0.0, 0.0] for k in range(args.n)]
    batt = json.loads(args.battery) if args.battery.strip().startswith("[") \
        else float(args.battery)
    em = Emulator(pose0=pose0, flavor=args.flavor, base_port=args.base_port,
                  battery=batt, offboard_timeout=args.offboard_timeout,
                  offboard_loss_action=args.offboard_loss_action,
                  guided_timeout=args.guided_timeout, gcs_timeout=args.gcs_timeout,
                  gcs_loss_action=args.gcs_loss_action, origin=args.origin,
                  silent=_parse_faults(args.silent), stale=_parse_faults(args.stale),
                  no_pose=[int(s) for s in (args.no_pose or "").split(",") if s.strip()],
                  log=args.log, pose_message=args.pose_message)
    banner = (f"emulating {em.n} {args.flavor} vehicle(s) on udp 127.0.0.1:"
              f"{em.ports[0]}..{em.ports[-1]}")
    return run_emulator(em, banner, args.duration)


def add_parser(sub):
    """``avblocks mavlink emulate`` on the ``avblocks`` sub-parsers."""
    r = sub.add_parser("mavlink", help="MAVLink drone tools (emulate PX4/ArduPilot)")
    rs = r.add_subparsers(dest="mavlink_command", required=True)
    e = rs.add_parser("emulate", help="emulate N PX4 or ArduPilot multicopters on UDP")
    e.add_argument("--n", type=int, default=1, help="number of vehicles")
    e.add_argument("--flavor", default="px4", choices=list(FLAVORS))
    e.add_argument("--base-port", type=int, default=14540, dest="base_port",
                   help="vehicle i listens on 127.0.0.1:base_port+i")
    e.add_argument("--pose0", help="JSON list of [x, y, z] start positions (ENU) [m]")
    e.add_argument("--spacing", type=float, default=1.0,
                   help="without --pose0: vehicles on a line this far apart [m]")
    e.add_argument("--battery", default="1.0",
                   help="start charge (fraction), one or a JSON list per vehicle")
    e.add_argument("--offboard-timeout", type=float, default=0.5, dest="offboard_timeout",
                   help="PX4 COM_OF_LOSS_T [s]")
    e.add_argument("--offboard-loss-action", default="land", choices=list(ACTIONS),
                   dest="offboard_loss_action", help="PX4 COM_OBL_RC_ACT")
    e.add_argument("--guided-timeout", type=float, default=3.0, dest="guided_timeout",
                   help="ArduPilot: GUIDED velocity set-point timeout [s]")
    e.add_argument("--gcs-timeout", type=float, default=5.0, dest="gcs_timeout",
                   help="ArduPilot FS_GCS_TIMEOUT [s]")
    e.add_argument("--gcs-loss-action", default="land", choices=list(ACTIONS),
                   dest="gcs_loss_action", help="ArduPilot FS_GCS_ENABLE")
    e.add_argument("--origin", default="world", choices=["world", "start"],
                   help="local NED origin: the world origin or each vehicle's start")
    e.add_argument("--silent", action="append", metavar="SYSID@T",
                   help="the vehicle sends nothing from T s after its first set-point")
    e.add_argument("--stale", action="append", metavar="SYSID@T",
                   help="the vehicle stops sending positions T s after its first set-point")
    e.add_argument("--no-pose", dest="no_pose", metavar="SYSID,...",
                   help="vehicles that never send a position")
    e.add_argument("--pose-message", default="local", choices=["local", "odometry"],
                   dest="pose_message", help="LOCAL_POSITION_NED + ATTITUDE_QUATERNION, "
                                             "or ODOMETRY (velocity in the body frame)")
    e.add_argument("--duration", type=float, help="seconds to run (default: forever)")
    e.add_argument("--log", help="JSON-lines log (raw received messages, events)")
    e.set_defaults(fn=main)
    return r
