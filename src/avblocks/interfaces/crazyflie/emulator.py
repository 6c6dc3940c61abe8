"""Emulated Crazyflies behind an emulated Crazyswarm2 server, on Zenoh
(rmw_zenoh keys), for tests and demos without hardware.

What it speaks (as Crazyswarm2's ``crazyflie_server`` does, per vehicle
``cfN``): subscriptions ``/cfN/cmd_full_state`` (FullState) and
``/cfN/cmd_velocity_world`` (VelocityWorld); services ``/cfN/takeoff``,
``/cfN/land``, ``/cfN/notify_setpoints_stop``, ``/cfN/arm`` and their
broadcast versions ``/all/...``; publications ``/cfN/pose`` (PoseStamped,
world frame, like the server's ``default_topics.pose`` log block),
``/cfN/status`` (Status: battery voltage, supervisor bits) and, with
``mocap=True``, ``/poses`` (NamedPoseArray, as motion_capture_tracking
publishes it).

Each vehicle is the library's own model: a
:class:`~avblocks.vehicles.Quadrotor` (Crazyflie 2.1 mass and inertia)
flown by :class:`~avblocks.vehicles.QuadrotorVelocityControl`, integrated
with RK4 at ``rate`` Hz (the controller's wrench held over a step, as a
discrete controller's is); a position loop ``v_ref = v_d + a_d / kv +
kp (p_d - p)`` (``kv`` the controller's velocity gain) turns position
set-points with their velocity and acceleration into its velocity
set-point; the controller's yaw set-point follows the commanded yaw.

Behaviours modelled, each from its source (crazyflie-firmware 2026.08,
commit 2a18fc29; Crazyswarm2 commit f6154e2):

* **Crazyswarm2's server** (``crazyflie/src/crazyflie_server.cpp``): each
  service handler hands the command to the radio and returns the empty
  response at once (no word on whether the vehicle took it); ``/all/...``
  services broadcast to every vehicle; ``arm`` calls
  ``sendArmingRequest(arm)``.
* **high-level commander** (``planner.c``, ``crtp_commander_high_level.c``):
  ``plan_takeoff`` is refused unless the planner is idle (``state !=
  TRAJECTORY_STATE_IDLE``); ``plan_land`` only while it is already landing;
  both fly a 7th-order rest-to-rest polynomial (zero velocity,
  acceleration and jerk at both ends) from the current position to
  ``(x, y, height)`` in ``duration``, yaw held; when a landing trajectory
  ends the planner is idle and outputs the null set-point: motors off.
  Heights are absolute. While the supervisor cannot fly (not armed) the
  commander is blocked (``stabilizer.c``, ``crtpCommanderBlock``): a
  takeoff then does nothing.
* **priorities** (``commander.c``, ``commanderSetSetpoint``,
  ``commanderRelaxPriority``; ``crtp_commander.c``): a streamed set-point
  (full state, velocity) has the CRTP priority, above the high-level
  commander's, and **stops the high-level planner**: a set-point that
  arrives after ``land`` cancels the landing. ``notify_setpoints_stop``
  relaxes the priority (``remain_valid_millisecs`` is ignored, as the
  firmware's decoder says); then the planner's output wins: an idle
  planner's null set-point (motors off) until ``land``/``takeoff`` plans
  again.
* **set-point watchdog** (``supervisor.c``: ``COMMANDER_WDT_TIMEOUT_STABILIZE``
  500 ms, ``COMMANDER_WDT_TIMEOUT_SHUTDOWN`` 2000 ms;
  ``supervisor_state_machine.c``): a streamed set-point older than 0.5 s
  puts the vehicle in *warning, level out* (roll and pitch zero, no
  horizontal control, z kept, ``supervisorOverrideSetpoint``); older than
  2 s the motors stop (*exception: free fall*, then *locked* until
  reboot): the vehicle falls. Under the high-level commander the set-point
  is refreshed every tick: no timeout. A relaxed priority (notify) leaves
  *level out* for *flying* again. The age is on the vehicle's clock, which
  never stops: a pause of the emulator process itself (a loaded host, more
  than ``PAUSE_MIN`` between two of its ticks; logged ``emulator_paused``)
  is not counted, since the set-points sent meanwhile were only waiting
  to be read.
* **arming** (``supervisor.c`` ``supervisorRequestArming``, ``AUTO_ARMING``;
  ``docs/functional-areas/supervisor/arming.md``; ``configs/cf21bl_defconfig``
  ``CONFIG_MOTORS_REQUIRE_ARMING=y``; ``platform_defaults.h``
  ``PREFLIGHT_TIMEOUT_MS`` 30000, ``LANDING_TIMEOUT_MS`` 3000):
  ``arming="auto"`` (Crazyflie 2.x, the default) arms itself;
  ``arming="required"`` (Crazyflie 2.1 Brushless, Bolt) can fly only
  after an arming request, accepted only when pre-flight checks passed (on
  the ground, not locked); armed but not flying for 30 s it disarms; 3 s
  after a landing it disarms (the state machine goes Landed -> Reset); a
  disarm request in flight stops the motors (Flying -> Reset).
* **status bits** (``supervisor.c`` ``updateLogData``): can be armed (1),
  armed (2), auto-arm (4), can fly (8), flying (16), locked (64); "flying"
  stays set for 2 s after the motors stop at the end of a landing
  (``IS_FLYING_HYSTERESIS_THRESHOLD``: the state machine leaves *flying*
  for *landed* only then), and the landing timeout counts from there.
* **yaw** (``crtp_commander_generic.c``: full state sets the attitude
  quaternion in ``modeAbs``, velocity-world a yaw rate in deg/s): the
  vehicle turns to the full-state set-point's yaw, or at the set yaw rate.
* **refusing set-points before takeoff** (emulator rule, stricter than
  the firmware, which would fly on them once armed): a streamed set-point
  to a vehicle on the ground is logged as ``refused`` and ignored.

Not modelled: the radio's latency and losses, the deprecated v1
takeoff/land packets' turn to yaw 0, battery drain, ground effect,
downwash, crash detection, tumbling.

Faults: ``silent`` (``{name: t}``: from ``t`` s after the fleet's first
streamed set-point the vehicle is gone: it publishes nothing, ignores
set-points and answers no service, so its own watchdog runs) and
``stale`` (``{name: t}``: its pose publications stop, as when motion
capture loses it; it still answers). ``battery`` (``{name: volts}``).

The log (JSON lines; ``wall`` = ``time.time()``, ``t`` = emulator seconds
when written; the firmware's events also carry ``at``, the physics time
they happened at, on the same clock)
records every set-point received (accepted or refused), every service
request with its arguments, the planner's trajectories, the watchdog's
transitions, ground contacts and the final positions.
"""

from __future__ import annotations

import json
import threading
import time

import numpy as np

from ...core.errors import ParameterError
from ...vehicles import Quadrotor, QuadrotorVelocityControl
from .._emulator import run_emulator
from ..flight.cli import start_line
from . import _types
from ._link import CfLink, NoReply

#: Crazyflie 2.1 with a motion-capture marker deck: mass [kg], inertia
#: [kg m^2] (Foerster 2015 system identification), arm length [m].
CF21 = {"mass": 0.034, "inertia": (1.66e-5, 1.66e-5, 2.93e-5), "arm_length": 0.046}
#: Velocity-controller gains of the emulated vehicles (a Crazyflie tracks
#: faster than the library's default 1 kg vehicle).
GAINS = {"kv": 4.0, "k_att": 12.0, "k_rate": 40.0}
#: Supervisor timeouts of the firmware [s] (COMMANDER_WDT_TIMEOUT_STABILIZE,
#: COMMANDER_WDT_TIMEOUT_SHUTDOWN in supervisor.c).
WDT_LEVEL_OUT, WDT_SHUTDOWN = 0.5, 2.0
#: Physics steps one loop iteration may take to catch up with the clock.
MAX_STEPS = 4
#: A gap between two loop iterations longer than this [s] means the
#: emulator process itself was not running (a loaded host descheduled it).
#: A firmware's clock never stops, and the radio keeps queueing set-points
#: meanwhile, so the watchdog does not count such a pause as set-point age.
PAUSE_MIN = 0.25
#: Status.supervisor_info bits (crazyflie_interfaces/msg/Status).
CAN_BE_ARMED, IS_ARMED, AUTO_ARM, CAN_FLY, IS_FLYING, IS_LOCKED = 1, 2, 4, 8, 16, 64
#: The supervisor's arming timeouts [s] (platform_defaults.h:
#: PREFLIGHT_TIMEOUT_MS, LANDING_TIMEOUT_MS).
PREFLIGHT_TIMEOUT, LANDING_TIMEOUT = 30.0, 3.0
#: The supervisor calls a vehicle flying until its motors have been below
#: idle thrust this long [s] (supervisor.c IS_FLYING_HYSTERESIS_THRESHOLD).
FLYING_HYSTERESIS = 2.0
ARMING = ("auto", "required")
SERVICES = {"takeoff": _types.TAKEOFF, "land": _types.LAND,
            "notify_setpoints_stop": _types.NOTIFY, "arm": _types.ARM}
#: Vehicle modes of the emulator (``drop``: motors stopped at the end of a
#: landing above the floor; it settles, then is ``landed``).
MODES = ("landed", "hl", "stream", "level_out", "falling", "drop", "locked")


def smooth7(s):
    """The 7th-order rest-to-rest polynomial (zero velocity, acceleration
    and jerk at s = 0 and 1) and its first two derivatives in s, for s in
    [0, 1] (constant outside)."""
    s = np.clip(s, 0.0, 1.0)
    f = s ** 4 * (35 - 84 * s + 70 * s ** 2 - 20 * s ** 3)
    df = 140 * s ** 3 * (1 - s) ** 3
    ddf = 420 * s ** 2 * (1 - s) ** 2 * (1 - 2 * s)
    return f, df, ddf


def _names(names):
    names = [s.strip() for s in (names.split(",") if isinstance(names, str) else names)]
    if not names or any(not s for s in names) or len(set(names)) != len(names):
        raise ParameterError("give unique vehicle names", param="names", found=names)
    return names


def _per_name(d, names, what):
    d = dict(d or {})
    unknown = set(d) - set(names)
    if unknown:
        raise ParameterError(f"{what} names a vehicle that is not emulated", param=what,
                             expected=names, found=sorted(unknown))
    return d


class CrazyflieEmulator:
    """Emulated Crazyflies and Crazyswarm2 server on one Zenoh session (see
    the module docstring).

    Parameters
    ----------
    names : list of str or "cf1,cf2"
    position0 : (N, 3), optional
        Start positions [m] (default: on the floor along x, centred on 0,
        ``spacing`` apart: where the drone_formation scenario starts N agents).
    router : str
        Zenoh router endpoint.
    rate : float
        Physics and watchdog rate [Hz].
    pose_rate : float
        ``/cfN/pose`` rate [Hz] (at most ``rate``); ``/cfN/status`` comes at 2 Hz.
    kp : float
        Position gain of the trajectory / full-state tracking [1/s].
    battery : dict, optional
        ``{name: volts}`` (default 4.0 V each).
    silent, stale : dict, optional
        Faults (see the module docstring).
    yaw0 : float or (N,) [rad]
        Start yaws.
    arming : {"auto", "required"}
        Auto-arming platform (Crazyflie 2.x) or one that needs an arming
        request (Crazyflie 2.1 Brushless).
    mocap : bool
        Also publish ``/poses`` (NamedPoseArray) at ``pose_rate``.
    log : path, optional
    domain : int, optional
    spacing : float [m]
        Without ``position0``: the distance between neighbours on the line.
    """

    def __init__(self, names, position0=None, *, router="tcp/127.0.0.1:7447", rate=100.0,
                 pose_rate=50.0, kp=2.5, battery=None, silent=None, stale=None, yaw0=0.0,
                 arming="auto", mocap=False, log=None, domain=None, spacing=1.0):
        self.names = _names(names)
        n = self.n = len(self.names)
        if position0 is None:
            position0 = start_line(n, spacing)
        p0 = np.array(position0, float)
        if p0.shape != (n, 3) or not np.isfinite(p0).all():
            raise ParameterError("position0 must be (N, 3) finite", param="position0",
                                 found=p0.shape)
        yaw0 = np.broadcast_to(np.asarray(yaw0, float), (n,)).copy()
        if not np.isfinite(yaw0).all():
            raise ParameterError("yaw0 must be finite", param="yaw0", found=yaw0)
        if arming not in ARMING:
            raise ParameterError("unknown arming kind", param="arming",
                                 expected=list(ARMING), found=arming)
        att0 = np.column_stack([np.cos(yaw0 / 2), np.zeros(n), np.zeros(n),
                                np.sin(yaw0 / 2)])
        self.quad = Quadrotor(p0, attitude0=att0, input="wrench", frame="crazyflie", **CF21)
        self.ctrl = QuadrotorVelocityControl.for_quadrotor(self.quad, yaw=yaw0, **GAINS)
        self.yaw_sp = yaw0.copy()              # the controller's yaw set-point
        self.auto_arm = arming == "auto"
        self.armed = np.full(n, self.auto_arm)
        self.t_armed = np.zeros(n)             # when armed (pre-flight timeout)
        self.t_landed = np.full(n, -np.inf)    # when the motors last stopped on landing
        self.flown = np.zeros(n, bool)         # took off since it was armed
        self.mocap = bool(mocap)
        self.x = {k: np.array(v, float) for k, v in self.quad.initial_state().items()}
        self.h = 1.0 / float(rate)
        self.pose_period = 1.0 / float(pose_rate)
        self.kp = float(kp)
        self.kv = float(self.ctrl.kv)
        volts = _per_name(battery, self.names, "battery")
        self.volts = np.array([float(volts.get(nm, 4.0)) for nm in self.names])
        self.silent = _per_name(silent, self.names, "silent")
        self.stale = _per_name(stale, self.names, "stale")
        self.mode = ["landed"] * n
        self.crtp = np.zeros(n, bool)          # streamed set-points have the priority
        self.sp = [None] * n                   # last streamed set-point (dict)
        self.traj = [None] * n                 # planner: dict or None (idle)
        self.gone = np.zeros(n, bool)          # silent fault active
        self.no_pose = np.zeros(n, bool)       # stale fault active
        self.t_first_sp = None
        #: Seconds of wall time the physics could not keep up with (slipped).
        self.lost = 0.0
        #: Seconds the emulator process itself was stopped (gaps between
        #: loop iterations over :data:`PAUSE_MIN`); the watchdogs' set-point
        #: age leaves them out (see :meth:`_references`).
        self.paused = 0.0
        self._lock = threading.RLock()
        self._log = open(log, "a", buffering=1) if log else None
        self._stop = threading.Event()
        self.wall0 = time.monotonic()
        self.link = CfLink(router, domain=domain, node="crazyflie_server")
        self.pose_pubs = [self.link.publisher(f"/{nm}/pose", _types.POSE_STAMPED)
                          for nm in self.names]
        self.status_pubs = [self.link.publisher(f"/{nm}/status", _types.STATUS)
                            for nm in self.names]
        self.mocap_pub = (self.link.publisher("/poses", _types.NAMED_POSE_ARRAY)
                          if self.mocap else None)
        fns = {"takeoff": self._takeoff, "land": self._land,
               "notify_setpoints_stop": self._notify, "arm": self._arm}
        for i, nm in enumerate(self.names):
            self.link.subscribe(f"/{nm}/cmd_full_state", _types.FULL_STATE,
                                lambda d, now, i=i: self._on_setpoint(i, "full_state", d))
            self.link.subscribe(f"/{nm}/cmd_velocity_world", _types.VELOCITY_WORLD,
                                lambda d, now, i=i: self._on_setpoint(i, "velocity", d))
            for topic, srv in SERVICES.items():
                self.link.serve(f"/{nm}/{topic}", srv,
                                lambda req, i=i, topic=topic: self._service(
                                    i, topic, fns[topic], req))
        # crazyflie_server.cpp: the /all/... services broadcast to every vehicle
        for topic, srv in SERVICES.items():
            self.link.serve(f"/all/{topic}", srv,
                            lambda req, topic=topic: self._broadcast(topic, fns[topic], req))
        self.write({"ev": "start", "vehicles": self.names, "position": p0.tolist(),
                    "yaw": yaw0.tolist(), "arming": arming})

    # ------------------------------------------------------------------ helpers
    def now(self):
        """Emulator time [s] since start."""
        return time.monotonic() - self.wall0

    def write(self, rec):
        if self._log is not None:
            rec = {"wall": time.time(), "t": round(self.now(), 6), **rec}
            with self._lock:
                if self._log is not None:
                    self._log.write(json.dumps(rec) + "\n")

    def _ignore(self, i):
        return bool(self.gone[i])

    # ------------------------------------------------------------------ inputs
    def _on_setpoint(self, i, kind, data):
        if self._ignore(i):
            return
        m = _types.deserialize(data, _types.FULL_STATE if kind == "full_state"
                               else _types.VELOCITY_WORLD)
        if kind == "full_state":
            p, v, q = m.pose.position, m.twist.linear, m.pose.orientation
            sp = {"kind": kind, "pos": [p.x, p.y, p.z], "vel": [v.x, v.y, v.z],
                  "acc": [m.acc.x, m.acc.y, m.acc.z],
                  "yaw": float(np.arctan2(2 * (q.w * q.z + q.x * q.y),
                                          1 - 2 * (q.y * q.y + q.z * q.z)))}
        else:
            sp = {"kind": kind, "vel": [m.vel.x, m.vel.y, m.vel.z],
                  "yaw_rate": float(m.yaw_rate)}
        t = self.now()
        with self._lock:
            mode = self.mode[i]
            ok = mode not in ("landed", "locked", "falling", "drop")
            if ok:
                sp["t"], sp["paused"] = t, self.paused
                self.sp[i] = sp
                self.crtp[i] = True
                if self.traj[i] is not None and self.traj[i]["kind"] == "land":
                    cancelled = True            # commander.c: the planner stops
                else:
                    cancelled = False
                self.traj[i] = None            # the planner stops (CRTP priority)
                self.mode[i] = "stream"
                if sp["kind"] == "full_state":
                    self.yaw_sp[i] = sp["yaw"]
                if self.t_first_sp is None:
                    self.t_first_sp = t
        rec = {"ev": "setpoint", "vehicle": self.names[i], **{k: v for k, v in sp.items()
                                                              if k not in ("t", "paused")},
               "accepted": ok,
               # the sender's clock when it was put (header.stamp): the
               # order it was sent in, which Zenoh's threads may not keep
               "stamp": m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec}
        if ok:      # the physics time the firmware stamped it with (its watchdog's
            rec["at"] = round(t, 6)     # reference; "t" is when the line is written)
        else:
            rec["reason"] = f"vehicle is {mode}"
        self.write(rec)
        if ok and cancelled:
            self.write({"ev": "landing_cancelled", "vehicle": self.names[i], "at": round(t, 6),
                        "by": "a streamed set-point (CRTP priority stops the planner)"})

    def _service(self, i, topic, fn, req):
        if self._ignore(i):
            raise NoReply                       # a vehicle that is gone answers nothing
        self.write({"ev": "service", "vehicle": self.names[i], "service": topic,
                    "request": req, "at": round(self.now(), 6)})
        fn(i, req)
        return None

    def _broadcast(self, topic, fn, req):
        self.write({"ev": "service", "vehicle": "all", "service": topic, "request": req,
                    "at": round(self.now(), 6)})
        for i in range(self.n):
            if not self._ignore(i):
                fn(i, req)
        return None

    def _plan(self, i, kind, height, duration):
        p0 = self.x["position"][i].copy()
        p1 = np.array([p0[0], p0[1], float(height)])
        self.traj[i] = {"kind": kind, "t0": self.now(), "dur": max(float(duration), 1e-3),
                        "p0": p0, "p1": p1}
        self.write({"ev": "plan", "vehicle": self.names[i], "kind": kind,
                    "from": p0.tolist(), "to": p1.tolist(), "duration": float(duration)})

    def _takeoff(self, i, req):
        with self._lock:
            if not self.armed[i] and self.mode[i] != "locked":
                self.write({"ev": "refused", "vehicle": self.names[i], "service": "takeoff",
                            "reason": "not armed: the supervisor cannot fly, the "
                                      "high-level commander is blocked"})
                return
            idle = self.traj[i] is None and self.mode[i] in ("landed",)
            if not idle:
                self.write({"ev": "refused", "vehicle": self.names[i], "service": "takeoff",
                            "reason": f"planner not idle (vehicle is {self.mode[i]})"})
                return
            self.crtp[i] = False
            self._plan(i, "takeoff", req["height"], req["duration"])
            self.mode[i] = "hl"
            self.flown[i] = True

    def _land(self, i, req):
        with self._lock:
            if self.mode[i] in ("landed", "locked", "falling", "drop"):
                return
            if self.traj[i] is not None and self.traj[i]["kind"] == "land":
                return                          # plan_land refuses while landing
            self._plan(i, "land", req["height"], req["duration"])
            if not self.crtp[i]:
                self.mode[i] = "hl"

    def _notify(self, i, req):
        with self._lock:
            self.crtp[i] = False
            if self.mode[i] in ("stream", "level_out"):
                self.mode[i] = "hl"

    def _arm(self, i, req):
        """supervisorRequestArming: arming only when pre-flight checks
        passed (on the ground, not locked); disarming always (in flight:
        Flying -> Reset, the motors stop)."""
        with self._lock:
            mode = self.mode[i]
            if req["arm"]:
                if self.armed[i]:
                    return
                if mode != "landed":
                    self.write({"ev": "refused", "vehicle": self.names[i], "service": "arm",
                                "reason": f"cannot arm: vehicle is {mode}"})
                    return
                self.armed[i], self.flown[i] = True, False
                self.t_armed[i] = self.now()
                self.write({"ev": "armed", "vehicle": self.names[i]})
                return
            if self.auto_arm or not self.armed[i]:
                return                          # auto-arming platforms arm again at once
            self._disarm(i, "disarm request")

    def _disarm(self, i, why):
        """Called with the lock held."""
        self.armed[i] = False
        mode = self.mode[i]
        if mode not in ("landed", "locked", "falling", "drop"):
            self.mode[i] = "drop"               # the motors stop: it falls, unlocked
            self.traj[i], self.crtp[i] = None, False
        self.write({"ev": "disarmed", "vehicle": self.names[i], "reason": why,
                    "mode": mode})

    # ------------------------------------------------------------------ firmware
    def _references(self, t):
        """Velocity references (N, 3), motors-on mask (N,) and events."""
        n = self.n
        p, v = self.x["position"], self.x["velocity"]
        vref = np.zeros((n, 3))
        on = np.zeros(n, bool)
        events = []
        for i in range(n):
            mode = self.mode[i]
            if mode in ("landed", "locked", "falling", "drop"):
                continue
            if self.crtp[i]:
                sp = self.sp[i]
                # the age on the vehicle's clock: the emulator's own pauses
                # (set-points queued, undelivered, while it was not running)
                # are not the link's silence
                age = t - sp["t"] - (self.paused - sp["paused"])
                if age > WDT_SHUTDOWN:
                    self.mode[i] = "falling"
                    events.append({"ev": "wdt_motors_off", "vehicle": self.names[i],
                                   "age": age, "z": float(p[i, 2])})
                    continue
                if age > WDT_LEVEL_OUT:
                    if mode != "level_out":
                        self.mode[i] = "level_out"
                        events.append({"ev": "wdt_level_out", "vehicle": self.names[i],
                                       "age": age})
                    vref[i, :2] = v[i, :2]      # no horizontal control
                    vref[i, 2] = (self.kp * (sp["pos"][2] - p[i, 2])
                                  if sp["kind"] == "full_state" else sp["vel"][2])
                else:
                    vref[i] = sp["vel"]
                    if sp["kind"] == "velocity":         # deg/s (velocityDecoder)
                        self.yaw_sp[i] += np.radians(sp["yaw_rate"]) * self.h
                    if sp["kind"] == "full_state":
                        vref[i] = vref[i] + (np.asarray(sp["acc"]) / self.kv
                                             + self.kp * (np.asarray(sp["pos"]) - p[i]))
                on[i] = True
                continue
            tr = self.traj[i]
            if tr is None:                      # idle planner: the null set-point
                continue
            s = (t - tr["t0"]) / tr["dur"]
            f, df, ddf = smooth7(s)
            dp = tr["p1"] - tr["p0"]
            pd = tr["p0"] + f * dp
            vd = df / tr["dur"] * dp
            ad = ddf / tr["dur"] ** 2 * dp
            if s >= 1.0 and tr["kind"] == "land":
                self.traj[i] = None             # planner idle: null set-point
                self.mode[i] = "drop" if p[i, 2] > 0.0 else "landed"
                self.t_landed[i] = t
                events.append({"ev": "land_done", "vehicle": self.names[i],
                               "position": p[i].tolist()})
                continue
            vref[i] = vd + ad / self.kv + self.kp * (pd - p[i])
            on[i] = True
        return vref, on, events

    def _supervisor(self, t):
        """The arming timeouts of a platform that needs arming (called with
        the lock held)."""
        if self.auto_arm:
            return
        for i in range(self.n):
            if not self.armed[i] or self.mode[i] != "landed":
                continue
            if not self.flown[i] and t - self.t_armed[i] > PREFLIGHT_TIMEOUT:
                self._disarm(i, "pre-flight timeout (30 s armed without flying)")
            elif self.flown[i] and t - self.t_landed[i] > FLYING_HYSTERESIS + LANDING_TIMEOUT:
                self._disarm(i, "landing timeout (3 s after landing)")

    def _rk4(self, vref, on, h):
        """RK4 of the vehicles over ``h`` with the controller's wrench held
        (the firmware's controller is discrete too: computed once a step)."""
        quad, x = self.quad, self.x
        self.ctrl.set_parameter("yaw", self.yaw_sp)
        w = self.ctrl.output(0.0, {}, {"velocity": vref, "measured_velocity": x["velocity"],
                                       "attitude": x["attitude"], "rates": x["rates"]},
                             np)["wrench"] * on[:, None]
        u = {"wrench": w}

        def f(x):
            return quad.derivative(0.0, x, u, np)

        k1 = f(x)
        k2 = f({k: x[k] + 0.5 * h * k1[k] for k in x})
        k3 = f({k: x[k] + 0.5 * h * k2[k] for k in x})
        k4 = f({k: x[k] + h * k3[k] for k in x})
        return {k: x[k] + h / 6 * (k1[k] + 2 * k2[k] + 2 * k3[k] + k4[k]) for k in x}

    def step(self, t, h=None):
        """One physics step of ``h`` seconds (default ``1 / rate``) from
        emulator time ``t``."""
        h = self.h if h is None else float(h)
        with self._lock:
            self._supervisor(t)
            vref, on, events = self._references(t)
            modes = list(self.mode)
        new = self._rk4(vref, on, h)
        for e in events:                        # the physics time of the event
            e["at"] = round(t, 6)
        ground = np.array([m in ("landed", "locked") for m in modes])
        for k in new:                           # vehicles on the ground stay put
            new[k][ground] = self.x[k][ground]
        below = (new["position"][:, 2] < 0.0) & ~ground
        if below.any():
            with self._lock:
                for i in np.nonzero(below)[0]:
                    mode = self.mode[i]
                    tr = self.traj[i]
                    if mode in ("falling", "drop") or not self.crtp[i] and (
                            tr is None or tr["kind"] == "land"):
                        events.append({"ev": "ground", "vehicle": self.names[i],
                                       "speed": float(-new["velocity"][i, 2]), "mode": mode,
                                       "at": round(t + h, 6)})
                        self.mode[i] = "locked" if mode == "falling" else "landed"
                        self.traj[i] = None
                        self.crtp[i] = False
                        if mode not in ("falling", "drop"):
                            self.t_landed[i] = t + h    # (drop: when its landing ended)
                    # else: pressed against the floor (a takeoff starting, a streamed
                    # set-point pointing down): the floor holds it, the mode stays
            new["position"][below, 2] = 0.0
            new["velocity"][below] = 0.0
            new["rates"][below] = 0.0
            q = new["attitude"][below]
            yaw = np.arctan2(2 * (q[:, 0] * q[:, 3] + q[:, 1] * q[:, 2]),
                             1 - 2 * (q[:, 2] ** 2 + q[:, 3] ** 2))
            new["attitude"][below] = np.column_stack(
                [np.cos(yaw / 2), np.zeros_like(yaw), np.zeros_like(yaw), np.sin(yaw / 2)])
        self.x = new
        for e in events:
            self.write(e)

    def _faults(self, t):
        if self.t_first_sp is None:
            return
        for d, flag, ev in ((self.silent, self.gone, "silent"),
                            (self.stale, self.no_pose, "stale")):
            for nm, after in d.items():
                i = self.names.index(nm)
                if not flag[i] and t - self.t_first_sp >= after:
                    flag[i] = True
                    self.write({"ev": ev, "vehicle": nm})

    def publish(self, t, status=False):
        q = self.x["attitude"] / np.linalg.norm(self.x["attitude"], axis=1, keepdims=True)
        for i in range(self.n):
            if self.gone[i]:
                continue
            if not self.no_pose[i]:
                self.pose_pubs[i].put(_types.encode_pose(self.x["position"][i], q[i], t))
            if status:
                self.status_pubs[i].put(_types.encode_status(t, self.volts[i],
                                                             self.status_bits(i)))
        if self.mocap_pub is not None:
            live = [i for i in range(self.n) if not self.gone[i] and not self.no_pose[i]]
            self.mocap_pub.put(_types.encode_named_poses(
                [self.names[i] for i in live], self.x["position"][live], q[live], t))

    def status_bits(self, i):
        """Status.supervisor_info of vehicle i (supervisor.c updateLogData)."""
        mode = self.mode[i]
        if mode == "locked":
            return IS_LOCKED | (AUTO_ARM if self.auto_arm else 0)
        bits = AUTO_ARM if self.auto_arm else 0
        if self.armed[i]:
            bits |= IS_ARMED | CAN_FLY
        elif mode == "landed":
            bits |= CAN_BE_ARMED
        if mode not in ("landed", "falling", "drop") or (
                self.armed[i] and self.now() - self.t_landed[i] < FLYING_HYSTERESIS):
            bits |= IS_FLYING
        return bits

    def run(self, duration=None):
        """Run until :meth:`stop` or ``duration`` seconds. The physics keeps
        the wall clock: each tick integrates the time since the last one,
        in up to :data:`MAX_STEPS` steps of at most ``2 / rate``; on a
        machine too loaded even for that the vehicles' time slips behind
        the clock (their integration stays stable; :attr:`lost` adds it up,
        and the log's ``end`` record has it)."""
        nxt = time.monotonic()
        end = None if duration is None else nxt + duration
        t_sim = t_pose = t_status = t_prev = self.now()
        while not self._stop.is_set() and (end is None or time.monotonic() < end):
            t = self.now()
            gap, t_prev = t - t_prev, t
            if gap > PAUSE_MIN:                 # this process was not running
                with self._lock:
                    self.paused += gap - self.h
                self.write({"ev": "emulator_paused", "s": round(gap, 6)})
            self._faults(t)
            behind = t - t_sim - MAX_STEPS * 2 * self.h
            if behind > 0:                      # the vehicles' time slips by this
                self.lost += behind
                t_sim += behind
            steps = min(MAX_STEPS, int(np.ceil((t - t_sim) / self.h - 1e-9)))
            if steps > 0:
                hh = (t - t_sim) / steps
                for _ in range(steps):
                    self.step(t_sim + hh, hh)
                    t_sim += hh
            if t - t_pose >= self.pose_period - 0.5 * self.h:
                status = t - t_status >= 0.5
                self.publish(t, status=status)
                t_pose = t
                t_status = t if status else t_status
            nxt += self.h
            delay = nxt - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            elif delay < -0.5:                  # far behind: resynchronize the ticks
                nxt = time.monotonic()
        self.write({"ev": "end", "position": self.x["position"].tolist(),
                    "modes": list(self.mode), "lost_s": round(self.lost, 6),
                    "paused_s": round(self.paused, 6)})

    def stop(self):
        self._stop.set()

    def close(self):
        self.link.close()
        with self._lock:
            if self._log is not None:
                self._log.close()
                self._log = None


def read_log(path):
    """The emulator's JSON-lines log as a list of dicts."""
    with open(path) as f:
        return [json.loads(s) for s in f if s.strip()]


def _parse_at(items, what):
    """``["cf2@3", "cf3@1.5s"]`` -> ``{"cf2": 3.0, "cf3": 1.5}``."""
    out = {}
    for it in items or []:
        for part in str(it).split(","):
            if not part.strip():
                continue
            if "@" not in part:
                raise ParameterError(f"a {what} fault is NAME@SECONDS, e.g. cf2@3",
                                     param=what, found=part)
            nm, t = part.split("@", 1)
            out[nm.strip()] = float(t.strip().rstrip("s"))
    return out


def _parse_eq(items, what):
    """``["cf3=3.4"]`` -> ``{"cf3": 3.4}``."""
    out = {}
    for it in items or []:
        for part in str(it).split(","):
            if not part.strip():
                continue
            if "=" not in part:
                raise ParameterError(f"{what} is NAME=VALUE, e.g. cf3=3.4", param=what,
                                     found=part)
            nm, v = part.split("=", 1)
            out[nm.strip()] = float(v)
    return out


def main(args):
    """``avblocks crazyflies emulate`` (see :func:`add_parser`)."""
    names = _names(args.names)
    p0 = json.loads(args.position0) if args.position0 else None
    yaw0 = json.loads(args.yaw0) if args.yaw0 else 0.0
    em = CrazyflieEmulator(names, p0, router=args.router, rate=args.rate,
                           pose_rate=args.pose_rate, battery=_parse_eq(args.battery, "battery"),
                           silent=_parse_at(args.silent, "silent"),
                           stale=_parse_at(args.stale, "stale"), yaw0=yaw0,
                           arming=args.arming, mocap=args.mocap, log=args.log,
                           domain=args.domain, spacing=args.spacing)
    banner = (f"emulating Crazyflies {','.join(em.names)} (Crazyswarm2 over rmw_zenoh) "
              f"via {args.router}")
    return run_emulator(em, banner, args.duration)


def add_parser(sub):
    """Add ``crazyflies emulate`` to the ``avblocks`` command's subparsers."""
    r = sub.add_parser("crazyflies", help="Crazyflie tools (emulate a Crazyswarm2 fleet "
                                          "over Zenoh)")
    rs = r.add_subparsers(dest="crazyflies_command", required=True)
    e = rs.add_parser("emulate", help="emulate Crazyflies behind a Crazyswarm2 server "
                                      "(rmw_zenoh keys)")
    e.add_argument("--names", required=True, help="vehicle names, e.g. cf1,cf2,cf3")
    e.add_argument("--router", default="tcp/127.0.0.1:7447", help="Zenoh router endpoint")
    e.add_argument("--position0", help="JSON list of [x, y, z] per vehicle (default: on "
                                       "the floor along x, centred on 0, --spacing apart: "
                                       "drone_formation's start line)")
    e.add_argument("--yaw0", help="start yaw [rad]: a number or a JSON list per vehicle")
    e.add_argument("--arming", default="auto", choices=list(ARMING),
                   help="auto: arms itself (Crazyflie 2.x); required: needs /cfN/arm "
                        "(Crazyflie 2.1 Brushless)")
    e.add_argument("--mocap", action="store_true",
                   help="also publish /poses (NamedPoseArray, motion capture)")
    e.add_argument("--spacing", type=float, default=1.0,
                   help="without --position0: vehicles on a line this far apart [m]")
    e.add_argument("--rate", type=float, default=100.0, help="physics rate [Hz]")
    e.add_argument("--pose-rate", type=float, default=50.0, dest="pose_rate",
                   help="/cfN/pose rate [Hz]")
    e.add_argument("--battery", action="append", metavar="NAME=VOLTS",
                   help="battery voltage of a vehicle (default 4.0 V)")
    e.add_argument("--silent", action="append", metavar="NAME@T",
                   help="vehicle NAME is gone T s after the first set-point")
    e.add_argument("--stale", action="append", metavar="NAME@T",
                   help="vehicle NAME's poses stop T s after the first set-point")
    e.add_argument("--domain", type=int, default=None, help="ROS domain id")
    e.add_argument("--duration", type=float, help="seconds to run (default: forever)")
    e.add_argument("--log", help="JSON-lines log")
    e.set_defaults(fn=main)
    from .guard import add_parser as add_guard
    add_guard(rs)
    return r
