"""The protocol-free part of a drone-fleet block: ports, flight phases,
limits, fail-safe, log. See the package docstring for the overview."""

from __future__ import annotations

import json
import threading
import time

import numpy as np

from ...core.block import Block
from ...core.errors import ParameterError
from . import _guard
from .errors import FailsafeError, FlightError, LimitError, PreflightError
from .limits import FlightLimits
from .telemetry import Telemetry

#: The phases a run goes through, in order (``failsafe`` can follow any).
PHASES = ("idle", "preflight", "takeoff", "mission", "land", "landed", "failsafe")


def quat_yaw(q):
    """Yaw [rad] of unit quaternions (N, 4) (w, x, y, z), body -> world."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def fleet_names(names, what="vehicle"):
    """``"cf1,cf2"`` or a list -> a list of unique, non-empty names."""
    if isinstance(names, str):
        names = [s for s in names.split(",") if s.strip()]
    names = [str(s).strip() for s in names]
    if not names or any(not s for s in names):
        raise ParameterError(f"give one name per {what}", param="names", found=names)
    dup = sorted({s for s in names if names.count(s) > 1})
    if dup:
        raise ParameterError(f"{what} names must be unique", param="names", found=dup)
    return names


class FleetLink:
    """What a protocol provides to :class:`Fleet` (subclass and override).

    ``telemetry`` is a :class:`~avblocks.interfaces.flight.telemetry.TelemetryBuffer`
    that the link's threads fill (world frame). Every method is called from
    the main thread except :meth:`land`, which any thread may call (the
    signal handler, the watchdog) and which must not block for long.
    """

    telemetry = None
    #: Seconds without a word after which a vehicle counts as gone (set by
    #: the block from its ``link_timeout`` before the takeoff).
    link_timeout = 2.0

    def open(self):
        """Connect; start the threads that fill ``telemetry``."""
        raise NotImplementedError

    def takeoff(self, height, timeout):
        """Arm every vehicle and climb to ``height`` [m above its start];
        return when all are there. Raise :class:`FlightError` naming the
        vehicle, the command and the reason on a refusal or a timeout."""
        raise NotImplementedError

    def send_velocity(self, v):
        """Send the world-frame velocity set-points ``v`` (N, 3) [m/s] (keep
        streaming them if the protocol needs a rate)."""
        raise NotImplementedError

    def preflight(self, telemetry):
        """The protocol's own pre-flight checks (called after the shared ones,
        before anything is commanded; may wait, bounded): a list of reasons,
        each naming its vehicle, empty when all is well."""
        return []

    def lost_control(self):
        """Vehicles that left the block's control in flight, as ``[(index,
        reason)]`` (disarmed, or switched out of the mode the block put them
        in: their own fail-safe, a pilot, another ground station); empty
        when the protocol cannot tell. Called each command step and during
        the takeoff."""
        return []

    def land(self, action="land"):
        """Command every vehicle to land now (``action="rtl"``: return to
        launch where the protocol has it), stop streaming set-points.
        Idempotent; any thread; no waiting for acknowledgements."""
        raise NotImplementedError

    def close(self):
        """Stop the threads and close the connections."""
        raise NotImplementedError


class Fleet(Block):
    """N drones commanded through a protocol, with the ports of
    :func:`~avblocks.vehicles.velocity_controlled_quadrotor` (base class).

    Ports
    -----
    velocity : in, (N, 3) [m/s]
        World-frame (ENU) velocity set-points.
    position : out, (N, 3) [m]
        Latest reported positions, world frame.
    pose : out, (N, 3) [m, m, rad]
        (x, y, yaw) from the latest position and attitude.
    attitude : out, (N, 4)
        Unit quaternion (w, x, y, z), body FLU -> world ENU.
    fresh : out, (N,) bool
        A pose arrived within ``timeout``.
    age : out, (N,) [s]
        Time since each vehicle's latest pose.

    State
    -----
    The outputs, as discrete states updated once per major step (or per
    ``period``) from the telemetry buffer; side effects (sending) happen in
    ``on_start``, ``on_major_step`` and ``on_stop`` only.

    Parameters
    ----------
    names : list of str or "a,b,c"
        Vehicle names, in agent order.
    takeoff_height : float [m]
        Height of the takeoff phase (above each vehicle's start).
    speed_max, accel_max, geofence, min_separation, lookahead, fence_margin
        Flight limits (:class:`~avblocks.interfaces.flight.limits.FlightLimits`).
    battery_min : float
        Pre-flight: a reported charge below this fraction refuses the start.
    battery_wait : float [s]
        Pre-flight: once every pose is in, wait this long at most for every
        vehicle's charge (vehicles that report none are not held to it).
    timeout : float [s]
        ``fresh`` is false for a pose older than this.
    stale_timeout : float [s]
        In flight, a pose older than this lands the fleet (fail-safe; the
        reason is "silent" when nothing else was heard since that pose,
        allowing a quarter of ``stale_timeout`` for the last burst's
        messages to be taken in).
    link_timeout : float [s]
        In flight, a vehicle not heard for this long lands the fleet
        (heartbeats count: for protocols with poses slower than heartbeats).
    stall_timeout : float [s]
        A watchdog thread lands the fleet if no command step happened for
        this long (the diagram hangs).
    wait : float [s]
        Pre-flight: how long to wait for every vehicle to answer.
    takeoff_timeout, land_wait : float [s]
        Takeoff must finish within this; at the normal end, wait this long
        at most for every vehicle to report landed.
    failsafe : {"land", "rtl"}
        What the fail-safe commands (``"rtl"`` where the protocol has it).
    slots : (N, 2) or (N, 3), optional
        The scenario's start positions, in agent order [m, world frame].
        Pre-flight matches the vehicles to them by their reported (x, y)
        (heights are ignored: vehicles start on the floor), minimising the
        summed distance (``scipy.optimize.linear_sum_assignment``): the
        vehicle standing at slot k flies agent k, whatever its name's
        place in ``names``. The mapping is logged (``slots`` event). None:
        agent k is ``names[k]``.
    slot_tolerance : float [m]
        Pre-flight refuses a vehicle further than this from its slot
        (inf: take any placement); only with ``slots``.
    log : path, optional
        JSON-lines flight log, written (and flushed) as things happen, so a
        killed process leaves it behind.
    period : float, optional
        Control period (a multiple of the run's ``dt``); default every step.

    Equations
    ---------
    Sent set-point ``v_i`` = the input shaped by the limits (speed scaled
    to ``speed_max``, change limited to ``accel_max dt``, cut at the
    geofence within ``lookahead``); no set-point after the fail-safe.
    With ``slots`` ``s_k``: the permutation ``pi`` minimising
    ``sum_k |p_pi(k) - s_k|`` over the vehicles' (x, y) positions ``p``;
    agent k's command goes to vehicle ``pi(k)``, whose telemetry is agent
    k's output.

    References
    ----------
    AVLib paper, Sections III.D and IV.D (vehicle interface blocks with the
    model's ports).
    """

    side_effects = True
    #: Actions the protocol supports for ``failsafe``.
    failsafe_actions = ("land", "rtl")

    def __init__(self, names, *, takeoff_height=1.0, speed_max=1.0, accel_max=np.inf,
                 geofence=None, min_separation=0.0, lookahead=1.0, fence_margin=0.2,
                 battery_min=0.2, timeout=0.5, stale_timeout=1.0, link_timeout=2.0,
                 stall_timeout=1.0, wait=10.0, takeoff_timeout=30.0, land_wait=20.0,
                 failsafe="land", log=None, period=None, battery_wait=1.5, slots=None,
                 slot_tolerance=0.5):
        super().__init__()
        self.names = fleet_names(names)
        self.n = n = len(self.names)
        blk = type(self).__name__
        if failsafe not in self.failsafe_actions:
            raise ParameterError("unknown fail-safe action", block=blk, param="failsafe",
                                 expected=list(self.failsafe_actions), found=failsafe)
        self.failsafe = failsafe
        self.limits = FlightLimits(n, speed_max, accel_max, geofence, min_separation,
                                   lookahead, fence_margin)
        for name, v in (("takeoff_height", takeoff_height), ("timeout", timeout),
                        ("stale_timeout", stale_timeout), ("link_timeout", link_timeout),
                        ("stall_timeout", stall_timeout), ("wait", wait),
                        ("takeoff_timeout", takeoff_timeout), ("land_wait", land_wait),
                        ("battery_wait", battery_wait)):
            if not (np.isfinite(v) and v >= 0):
                raise ParameterError("must be a finite number >= 0", block=blk, param=name,
                                     found=v)
            setattr(self, name, float(v))
        if not 0 <= battery_min < 1:
            raise ParameterError("battery_min is a fraction in [0, 1)", block=blk,
                                 param="battery_min", found=battery_min)
        self.battery_min = float(battery_min)
        if slots is not None:
            sl = np.asarray(slots, float)
            if sl.ndim != 2 or sl.shape[0] != n or sl.shape[1] not in (2, 3) \
                    or not np.isfinite(sl).all():
                raise ParameterError("slots are the N start positions (N, 2) or (N, 3)",
                                     block=blk, param="slots", expected=(n, 3),
                                     found=np.shape(sl))
            slots = sl[:, :2].copy()
        self.slots = slots
        if not (slot_tolerance >= 0) or np.isnan(slot_tolerance):
            raise ParameterError("must be a number >= 0 (inf: any placement)", block=blk,
                                 param="slot_tolerance", found=slot_tolerance)
        self.slot_tolerance = float(slot_tolerance)
        #: Agent k is flown by vehicle ``names[order[k]]`` (set by pre-flight).
        self.order = np.arange(n)
        self.log_path = log
        xyz = ("x", "y", "z")
        self.declare_input("velocity", (n, 3), unit="m/s", labels=xyz, feedthrough=False,
                           doc="velocity set-point, world frame (ENU)")
        self.declare_output("position", (n, 3), unit="m", labels=xyz)
        self.declare_output("pose", (n, 3), unit="m, m, rad", labels=("x", "y", "yaw"),
                            doc="planar pose (x, y, yaw)")
        self.declare_output("attitude", (n, 4), labels=("w", "x", "y", "z"),
                            doc="unit quaternion, body -> world")
        self.declare_output("fresh", (n,), dtype="bool")
        self.declare_output("age", (n,), unit="s")
        self._outs = ("position", "pose", "attitude", "fresh", "age")
        self.declare_discrete_state("position", np.zeros((n, 3)))
        self.declare_discrete_state("pose", np.zeros((n, 3)))
        self.declare_discrete_state("attitude", np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)))
        self.declare_discrete_state("fresh", np.zeros(n, bool))
        self.declare_discrete_state("age", np.zeros(n))
        if period is not None:
            self.declare_periodic(float(period))
        self.link = None
        self.phase = "idle"
        #: Flight log of the last run: dicts with ``wall`` and ``ev`` (also in ``log``).
        self.events = []
        #: Velocity set-points sent at the last command step (N, 3).
        self.sent = None
        self.steps_sent = 0
        self._log = None
        self._lock = threading.Lock()
        self._landing = False
        self._failsafe_reason = self._failsafe_code = None
        self._aborting = False
        self._watch = None

    # ---------------------------------------------------------------- to override
    def open_link(self):
        """The :class:`FleetLink` of this protocol (subclasses)."""
        raise NotImplementedError

    # ---------------------------------------------------------------- log
    def record(self, ev, **kw):
        """Add an event to :attr:`events` and the log file (any thread)."""
        rec = {"wall": time.time(), "ev": ev, **kw}
        with self._lock:
            self.events.append(rec)
            if self._log is not None:
                try:
                    self._log.write(json.dumps(rec, default=float) + "\n")
                    self._log.flush()
                except (OSError, ValueError):  # pragma: no cover - disk full, closed
                    pass

    def _set_phase(self, phase, **kw):
        self.phase = phase
        self.record("phase", phase=phase, **kw)

    # ---------------------------------------------------------------- block functions
    def output(self, t, x, u, xp):
        return {k: x[k] for k in self._outs}

    def update(self, t, x, u, xp):
        # The one impure read (as in interfaces.ros2.Robots): the latest
        # telemetry becomes the next state, once per major step.
        if self.link is None:
            return {k: x[k] for k in self._outs}
        return self._state_from(self._snapshot())

    # ---------------------------------------------------------------- agent order
    @property
    def agent_names(self):
        """Vehicle names in agent order (after the pre-flight assignment)."""
        return [self.names[i] for i in self.order]

    def _snapshot(self):
        """The link's telemetry in agent order."""
        tm = self.link.telemetry.snapshot()
        o = self.order
        return Telemetry(tm.position[o], tm.velocity[o], tm.attitude[o], tm.pose_age[o],
                         tm.heard_age[o], tm.poses[o], tm.battery[o], tm.armed[o],
                         tm.landed[o], [tm.status[i] for i in o])

    def _to_link(self, v):
        """Agent-order rows -> the link's vehicle order."""
        out = np.empty_like(v)
        out[self.order] = v
        return out

    def _state_from(self, tm):
        pos = np.nan_to_num(tm.position)
        yaw = quat_yaw(tm.attitude)
        return {"position": pos, "pose": np.column_stack([pos[:, :2], yaw]),
                "attitude": tm.attitude, "fresh": tm.pose_age <= self.timeout,
                "age": np.minimum(tm.pose_age, 1e9)}

    # ---------------------------------------------------------------- phases
    def on_start(self):
        self.events, self.steps_sent, self.sent = [], 0, None
        self._landing = False
        self._failsafe_reason = self._failsafe_code = None
        self._aborting = False
        self.order = np.arange(self.n)
        self._v_prev, self._t_prev = None, None
        self._next_send = None
        if self.log_path is not None:
            self._log = open(self.log_path, "a", buffering=1)
        self.record("start", vehicles=self.names, block=type(self).__name__)
        try:
            self.link = self.open_link()
            self.link.link_timeout = self.link_timeout
            _guard.register(self)
            self.link.open()
            self._set_phase("preflight")
            self._preflight()
            self._set_phase("takeoff", height=self.takeoff_height)
            self.link.takeoff(self.takeoff_height, self.takeoff_timeout)
            tm = self._snapshot()
            self._set_phase("mission", position=tm.position.tolist(),
                            agents=self.agent_names)
        except BaseException as e:
            self.record("abort", phase=self.phase, error=f"{type(e).__name__}: {e}")
            self._aborting = True       # the error above is the one to report
            try:
                self.on_stop()
            finally:
                self._aborting = False
            raise
        for k, v in self._state_from(tm).items():
            self.set_initial(k, v)
        self._last_step = time.monotonic()
        self._watch_stop = threading.Event()
        self._watch = threading.Thread(target=self._watchdog, daemon=True,
                                       name="avblocks-fleet-watchdog")
        self._watch.start()

    def _preflight(self):
        """Every vehicle answers, has a fresh pose, enough battery, is inside
        the geofence and far enough from the others; else PreflightError
        naming each vehicle and its reason (nothing was commanded)."""
        deadline = time.monotonic() + self.wait
        while True:
            tm = self.link.telemetry.snapshot()
            if (tm.poses > 0).all() or time.monotonic() > deadline:
                break
            time.sleep(0.02)
        # batteries come slower than poses (1-2 Hz): give them battery_wait more
        b_deadline = min(deadline, time.monotonic() + self.battery_wait)
        while not np.isfinite(tm.battery).all() and time.monotonic() < b_deadline:
            time.sleep(0.05)
            tm = self.link.telemetry.snapshot()
        why = []
        for i, nm in enumerate(self.names):
            if not np.isfinite(tm.heard_age[i]):
                why.append(f"{nm}: does not answer (nothing heard within {self.wait:g} s)")
            elif tm.poses[i] == 0:
                why.append(f"{nm}: reports no pose (answers, but sent no position "
                           f"within {self.wait:g} s)")
            elif tm.pose_age[i] > self.stale_timeout:
                why.append(f"{nm}: pose is stale ({tm.pose_age[i]:.2f} s old, "
                           f"stale_timeout {self.stale_timeout:g} s)")
            b = tm.battery[i]
            if np.isfinite(b) and b < self.battery_min:
                why.append(f"{nm}: battery low ({100 * b:.0f} % < battery_min "
                           f"{100 * self.battery_min:.0f} %)")
        have = tm.poses > 0
        if have.any():
            idx = np.nonzero(have)[0]
            sub = [self.names[i] for i in idx]
            why += self.limits.outside(sub, tm.position[idx])
            why += [f"too close: {s}" for s in self.limits.too_close(sub, tm.position[idx])]
            why += self._takeoff_in_fence(sub, tm.position[idx])
        if self.slots is not None and have.all():
            why += self._assign(tm.position)
        why += self.link.preflight(tm)
        if why:
            self.record("preflight_refused", reasons=why)
            raise PreflightError("pre-flight check failed, nothing was commanded: "
                                 + "; ".join(why), block=type(self).__name__,
                                 hint="fix the vehicles named (or the limits) and start "
                                      "again")
        self.record("preflight_ok", position=tm.position.tolist(),
                    battery=[None if not np.isfinite(b) else float(b) for b in tm.battery])

    def _takeoff_in_fence(self, names, position):
        """Refusals for vehicles whose takeoff height (above where each
        stands) would carry them through the geofence's ceiling."""
        g = self.limits.geofence
        if g is None or not np.isfinite(g[5]):
            return []
        z = np.asarray(position, float)[:, 2] + self.takeoff_height
        return [f"{nm}: takeoff to z={zi:.2f} m ({self.takeoff_height:g} m above where it "
                f"stands) would cross the geofence's ceiling ({g[5]:g} m): lower the "
                f"takeoff height or raise the fence"
                for nm, zi in zip(names, z) if zi > g[5]]

    def _assign(self, position):
        """Match the vehicles to the start slots (see ``slots``); sets
        :attr:`order`, logs the mapping; returns the refusals."""
        from scipy.optimize import linear_sum_assignment
        p = np.asarray(position, float)[:, :2]
        cost = np.linalg.norm(p[:, None, :] - self.slots[None, :, :], axis=-1)
        veh, slot = linear_sum_assignment(cost)          # vehicle veh[j] -> slot slot[j]
        order = np.empty(self.n, int)
        order[slot] = veh
        dist = cost[order, np.arange(self.n)]            # agent k: vehicle order[k]
        self.order = order
        mapping = [{"agent": k, "vehicle": self.names[order[k]],
                    "slot": self.slots[k].round(3).tolist(),
                    "distance": round(float(dist[k]), 3)} for k in range(self.n)]
        self.record("slots", mapping=mapping, tolerance=self.slot_tolerance,
                    reordered=bool((order != np.arange(self.n)).any()))
        why = []
        for k in np.nonzero(dist > self.slot_tolerance)[0]:
            i = order[k]
            near = int(np.argmin(cost[i]))
            far = cost[i, near] > self.slot_tolerance
            why.append(f"{self.names[i]} at ({p[i, 0]:.2f}, {p[i, 1]:.2f}) is "
                       + (f"{cost[i, near]:.2f} m from the nearest start slot "
                          f"(agent {near}, at ({self.slots[near, 0]:.2f}, "
                          f"{self.slots[near, 1]:.2f}))" if far else
                          f"{dist[k]:.2f} m from the start slot left for it (agent {k}, "
                          f"at ({self.slots[k, 0]:.2f}, {self.slots[k, 1]:.2f}); another "
                          f"vehicle stands nearer its nearest one)")
                       + f": more than slot_tolerance {self.slot_tolerance:g} m")
        return why

    # ---------------------------------------------------------------- mission
    def on_major_step(self, t, x, u, y):
        if self.link is None:
            return
        if self.phase == "failsafe" and self._failsafe_code is not None:
            # landed from another thread (the stall watchdog): the run ends
            # here, with the reason, not as if the vehicles still flew it
            raise FailsafeError(f"the fail-safe landed every vehicle ({self._failsafe_reason}) "
                                "and the run ended", reason=self._failsafe_code,
                                vehicles=list(self.names), block=type(self).__name__,
                                time=t, hint="the log up to then is in err.results (and "
                                             "the flight log)")
        if self.phase != "mission":
            return
        if self._next_send is not None and t < self._next_send - 1e-9:
            return
        per = getattr(self.sample_time, "period", None)
        self._next_send = t + per if per else None
        now = time.monotonic()
        self._last_step = now
        v = np.array(u["velocity"], dtype=float)
        names = self.agent_names
        bad = ~np.all(np.isfinite(v), axis=1)
        if bad.any():
            who = [nm for nm, b in zip(names, bad) if b]
            self._fail(t, "nan", who, f"the velocity command is NaN or infinite for {who}")
        lost = self.link.lost_control()
        if lost:
            who = [self.names[i] for i, _ in lost]
            self._fail(t, "control", who, "; ".join(why for _, why in lost))
        tm = self._snapshot()
        # every test first, then one fail-safe naming every vehicle concerned:
        # a router or emulator that dies takes all vehicles' poses at once, and
        # the one whose last pose happens to be oldest must not be the only one
        # named (the others are just behind it: list those without a fresh pose)
        silent = tm.heard_age > self.link_timeout
        stale = tm.pose_age > self.stale_timeout
        # a stale pose with nothing heard since it is a silent vehicle. "Since"
        # allows for the last burst: the messages a vehicle sent with its last
        # pose are stamped as its receive thread gets to them, milliseconds
        # later (tens on a loaded computer), so a quarter of stale_timeout
        # after the pose still counts as nothing; a vehicle that only lost its
        # pose keeps sending its other telemetry (MAVLink: 5 Hz and more;
        # Crazyflie status: 1-2 Hz), much later than that.
        silent |= stale & ((tm.heard_age > self.stale_timeout)
                           | (tm.heard_age > tm.pose_age - self.stale_timeout / 4))
        quiet = (tm.pose_age > self.timeout) | (tm.heard_age > self.timeout)
        for reason, hit, what in (
                ("silent", silent, lambda who, ix: f"nothing heard from {who} for "
                 + ", ".join(f"{tm.heard_age[i]:.2f}" for i in ix)
                 + f" s (link_timeout {self.link_timeout:g} s; or no pose for "
                   f"stale_timeout {self.stale_timeout:g} s and nothing since)"),
                ("stale", stale, lambda who, ix: f"no pose from {who} for more than "
                 f"stale_timeout={self.stale_timeout:g} s")):
            if hit.any():
                ix = np.nonzero(hit)[0]
                who = [names[i] for i in ix]
                also = [f"{nm} ({a:.2f} s)" for nm, s, q, a in
                        zip(names, hit, quiet, tm.pose_age) if q and not s]
                msg = what(who, ix) + ("; no fresh pose either from " + ", ".join(also)
                                   if also else "")
                self._fail(t, reason, [nm for nm, s, q in zip(names, hit, quiet)
                                       if s or q], msg)
        breach = self.limits.breaches(names, tm.position)
        if breach:
            who = [nm for nm, b in zip(names, self.limits.breaching(tm.position)) if b]
            self._fail(t, "limit", who, "a flight limit was broken: " + "; ".join(breach),
                       LimitError)
        dt = 0.0 if self._t_prev is None else now - self._t_prev
        c = self.limits.shape(v, self._v_prev, dt, tm.position)
        self.link.send_velocity(self._to_link(c))
        self._v_prev, self._t_prev = c, now
        self.sent = c
        self.steps_sent += 1
        self.record("cmd", t=float(t), v=np.round(c, 6).tolist())

    def _fail(self, t, reason, vehicles, what, cls=FailsafeError):
        self.land_all(reason, vehicles)
        raise cls(f"{what}; every vehicle was commanded to "
                            f"{self.failsafe.upper()} and the run ended",
                            reason=reason, vehicles=vehicles, block=type(self).__name__,
                            time=t, hint="the log up to now is in err.results (and the "
                                         "flight log)")

    def land_all(self, reason="fail-safe", vehicles=(), code=None):
        """Fail-safe: command every vehicle to land (or RTL) now and stop
        sending set-points. Any thread; idempotent. ``code`` (e.g.
        ``"stall"``): the next command step ends the run with a
        :class:`FailsafeError` of that reason (a fail-safe raised from
        another thread)."""
        link = self.link
        if link is None:
            return
        first = not self._landing
        self._landing = True
        if first:
            self._failsafe_reason, self._failsafe_code = reason, code
            self.phase = "failsafe"
        try:
            link.land(self.failsafe)
        finally:
            if first:
                self.record("failsafe", reason=reason, vehicles=list(vehicles),
                            action=self.failsafe)

    def stop_robots(self):
        """The signal guard's hook (``interfaces.flight._guard``): land all."""
        if self.phase in ("mission", "takeoff", "land"):   # preflight: nothing armed
            self.land_all("signal or exit")

    def _watchdog(self):
        while not self._watch_stop.wait(0.05):
            if self.phase != "mission":
                continue
            stalled = time.monotonic() - self._last_step
            if stalled > self.stall_timeout:
                self.land_all(f"no command step for {stalled:.2f} s (stall_timeout "
                              f"{self.stall_timeout:g} s)", code="stall")
                return

    # ---------------------------------------------------------------- end
    def on_stop(self):
        link = self.link
        unconfirmed = None
        try:
            if link is not None:
                if self.phase == "mission":      # the normal end: land, then wait
                    self._set_phase("land")
                    self._landing = True
                    link.land("land")
                    unconfirmed = self._wait_landed()
                elif not self._landing and self.phase == "takeoff":
                    self.land_all(f"run ended during {self.phase}")
                    self._wait_landed()
                elif self._landing:
                    link.land(self.failsafe)     # once more, for lossy links
                    self._wait_landed()
        finally:
            if self._watch is not None:
                self._watch_stop.set()
                self._watch = None
            _guard.unregister(self)
            self.link = None
            if link is not None:
                try:
                    link.close()
                finally:
                    self.record("end", phase=self.phase)
            else:
                self.record("end", phase=self.phase)
            if self._log is not None:
                self._log.close()
                self._log = None
        if unconfirmed and not self._aborting:
            # the run "completed" but some vehicles were not seen landing: say
            # so (avblocks run: "error while stopping", exit status 3)
            raise FlightError(f"the landing at the end of the run was not confirmed: "
                              f"{unconfirmed}", block=type(self).__name__,
                              hint="go and look at those vehicles; the flight log has "
                                   "their last positions")

    def _wait_landed(self):
        """Wait up to ``land_wait`` for every vehicle still heard to report
        landed, logging a ``landed`` event per vehicle as it does; then
        ``land_unconfirmed`` for those gone silent (nothing heard for
        ``link_timeout``: no confirmation can come) and ``land_timeout`` for
        those still flying. The phase becomes ``landed`` when all are."""
        t0 = time.monotonic()
        deadline = t0 + self.land_wait
        done = np.zeros(self.n, bool)
        while True:
            tm = self.link.telemetry.snapshot()
            for i in np.nonzero(tm.landed & ~done)[0]:
                done[i] = True
                self.record("landed", vehicle=self.names[i],
                            position=np.round(tm.position[i], 4).tolist(),
                            after_s=round(time.monotonic() - t0, 3))
            silent = ~done & (tm.heard_age > self.link_timeout)
            if done.all() or not (~done & ~silent).any() or time.monotonic() > deadline:
                break
            time.sleep(0.05)
        if done.all():
            if self.phase == "land":
                self._set_phase("landed", position=tm.position.tolist())
            else:
                self.record("all_landed", phase=self.phase)
            return None
        out = []
        if silent.any():
            who = [nm for nm, s in zip(self.names, silent) if s]
            self.record("land_unconfirmed", vehicles=who,
                        reason=f"silent (nothing heard for more than link_timeout "
                               f"{self.link_timeout:g} s)")
            out.append(", ".join(f"{self.names[i]} went silent at z={tm.position[i, 2]:.2f} m"
                                 for i in np.nonzero(silent)[0]))
        flying = ~done & ~silent
        if flying.any():
            self.record("land_timeout", flying=[nm for nm, f in zip(self.names, flying) if f],
                        land_wait=self.land_wait)
            out.append(", ".join(f"{self.names[i]} still not landed after {self.land_wait:g} s "
                                 f"(z={tm.position[i, 2]:.2f} m)"
                                 for i in np.nonzero(flying)[0]))
        return "; ".join(out)
