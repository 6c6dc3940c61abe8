"""The Crazyswarm2 protocol under :class:`~avblocks.interfaces.flight.Fleet`:
a :class:`~avblocks.interfaces.flight.FleetLink` speaking rmw_zenoh to a
``crazyflie_server`` (or to :mod:`.emulator`).

Per vehicle ``cfN`` (names as in Crazyswarm2's ``crazyflies.yaml``):

=========================================  =======================================
``/cfN/pose`` (PoseStamped) in             ``pose_source="pose"`` (default):
                                           position, attitude; velocity by finite
                                           difference of the stamps
``/poses`` (NamedPoseArray) in             ``pose_source="mocap"``: the motion-
                                           capture poses (motion_capture_tracking),
                                           the entry named ``cfN``
``/cfN/status`` (Status) in, optional      battery (voltage -> charge with the
                                           firmware's LiPo curve), supervisor bits
                                           (armed, auto-arming, can fly, flying)
``/cfN/cmd_full_state`` (FullState) out    ``setpoint="full_state"``: position
                                           integrated from the commanded velocity,
                                           the velocity, zero acceleration, the
                                           held yaw
``/cfN/cmd_velocity_world`` out            ``setpoint="velocity"``: the velocity,
                                           yaw rate 0 (the yaw is held)
``/cfN/arm`` (Arm) service                 before takeoff, where the platform needs
                                           it (``arm``); disarm once landed
``/cfN/takeoff`` (Takeoff) service         height = start z + takeoff height
``/cfN/notify_setpoints_stop`` service     after the last streamed set-point
``/cfN/land`` (Land) service               then the landing (fail-safe, normal end)
=========================================  =======================================

**Streaming.** One sender thread puts the held set-point at ``stream_rate``
(50 Hz); a diagram step only replaces what is held. A step that is slow
(a diagram pausing for a moment) therefore does not stop the stream; a set-
point older than ``hold`` is no longer repeated (a hung diagram: the
block's stall watchdog lands the fleet before that, and the firmware's own
watchdog, or the guard, after it).

**Landing order** (Crazyswarm2's contract: ``crazyflie_py/crazyflie.py``,
``notifySetpointsStop``: "called after sending the last low-level
setpoint, and before sending any high-level command"; its examples
``cmd_full_state.py`` and ``vel_mux.py`` do notify, then land): the sender
is stopped and joined first, so no set-point can follow; then
``notify_setpoints_stop`` goes to every vehicle, and each vehicle's
``land`` follows as soon as its notification is acknowledged (the reply
comes after the server handed it to the radio; ``land_ack_wait`` at most).
The other order is unsafe: in crazyflie-firmware's ``commander.c``
(``commanderSetSetpoint``) a streamed set-point stops the high-level
planner, and Crazyswarm2's C++ server serves topics and services on
separate callback groups, so a set-point overtaken by ``land`` cancels
the landing. Between the notification and ``land`` the idle planner's null
set-point holds for one round trip.
"""

from __future__ import annotations

import threading
import time

import numpy as np

from ..flight import (
    FleetLink,
    FlightError,
    PreflightError,
    RobotWarning,
    TelemetryBuffer,
    quat_yaw,
)
from . import _types

#: The firmware's typical LiPo charge curve (crazyflie-firmware 2026.08,
#: ``pm_stm32f4.c``): volts at 0 %, 10 %, ... 90 % charge (100 % at 4.2 V).
LIPO_VOLTS = (3.00, 3.78, 3.83, 3.87, 3.89, 3.92, 3.96, 4.00, 4.04, 4.10, 4.20)
SETPOINTS = {"full_state": ("cmd_full_state", _types.FULL_STATE),
             "velocity": ("cmd_velocity_world", _types.VELOCITY_WORLD)}
POSE_SOURCES = ("pose", "mocap")
#: Status.supervisor_info bits (crazyflie_interfaces/msg/Status.msg; the
#: firmware's ``supervisor.c`` ``updateLogData`` fills them).
CAN_BE_ARMED, IS_ARMED, AUTO_ARM, CAN_FLY, IS_FLYING, IS_TUMBLED, IS_LOCKED = (
    1, 2, 4, 8, 16, 32, 64)
#: Liveliness prefix under which a commander announces that it is landing
#: its vehicles (the guard then leaves them to it).
LANDING_PREFIX = "avblocks/landing"


def battery_fraction(volts):
    """Charge in [0, 1] of a 1S LiPo at ``volts`` (the firmware's curve,
    interpolated linearly)."""
    return float(np.interp(volts, LIPO_VOLTS, np.linspace(0.0, 1.0, len(LIPO_VOLTS))))


class CrazyflieLink(FleetLink):
    """Crazyswarm2 over rmw_zenoh for N Crazyflies (see the module docstring).

    Parameters
    ----------
    names : list of str
    router : str
        Zenoh router endpoint (``ros2 run rmw_zenoh_cpp rmw_zenohd``).
    setpoint : {"full_state", "velocity"}
    stream_rate : float [Hz]
        Rate of the set-point sender.
    hold : float [s]
        The sender stops repeating a set-point older than this.
    yaw : None, float or (N,) [rad]
        Yaw of the full-state set-points: None holds each vehicle's yaw at
        the first mission step.
    arm : {"auto", True, False}
        ``/cfN/arm`` before takeoff: "auto" arms the vehicles whose status
        says they need it (not armed, not auto-arming: a Crazyflie 2.1
        Brushless, a Bolt); True arms every vehicle; False never.
    arm_timeout : float [s]
        How long an armed vehicle may take to report it can fly.
    pose_source : {"pose", "mocap"}
        ``/cfN/pose`` (the onboard estimate Crazyswarm2 logs) or ``/poses``
        (the motion-capture poses).
    takeoff_speed : float [m/s]
        Mean climb speed: takeoff duration = height / takeoff_speed (1 s at least).
    land_duration : float [s]
    land_height : float [m]
        Height the landing trajectory ends at (the motors stop there;
        Crazyswarm2's examples use 0.03 m).
    service_timeout : float [s]
    domain, node, mode
        ROS domain id, node name, Zenoh mode.
    exclusive : bool
        Refuse to start when another avblocks process commands one of the vehicles.
    record : callable, optional
        ``record(ev, **fields)`` of the block's flight log.
    """

    def __init__(self, names, router="tcp/127.0.0.1:7447", *, setpoint="full_state",
                 stream_rate=50.0, hold=1.5, yaw=None, arm="auto", arm_timeout=3.0,
                 pose_source="pose", takeoff_speed=0.3, land_duration=3.0, land_height=0.03,
                 service_timeout=1.0, domain=None, node="avblocks", mode="client",
                 exclusive=True, record=None):
        self.names = list(names)
        self.n = n = len(self.names)
        self.router, self.domain, self.node, self.mode = router, domain, node, mode
        self.setpoint = setpoint
        self.stream_rate, self.hold = float(stream_rate), float(hold)
        self.yaw = None if yaw is None else np.broadcast_to(np.asarray(yaw, float), (n,))
        self.arm, self.arm_timeout = arm, float(arm_timeout)
        self.pose_source = pose_source
        self.takeoff_speed = float(takeoff_speed)
        self.land_duration, self.land_height = float(land_duration), float(land_height)
        self.service_timeout = float(service_timeout)
        self.land_ack_wait = min(0.3, self.service_timeout)
        self.exclusive = bool(exclusive)
        self.record = record or (lambda ev, **kw: None)
        self.telemetry = TelemetryBuffer(n)
        self._index = {nm: i for i, nm in enumerate(self.names)}
        self._link = None
        self._lock = threading.Lock()
        self._prev = np.full((n, 4), np.nan)     # x y z stamp of the previous pose
        self._status_seen = np.zeros(n, bool)
        self._sup = np.full(n, -1, np.int64)     # supervisor bits (-1: no status yet)
        self._z0 = np.full(n, np.nan)            # floor height (first pose, then takeoff)
        self._flying = np.zeros(n, bool)         # the status' "is flying" bit
        self._on_floor = np.ones(n, bool)        # the pose: on the floor and still
        self._armed_by_us = []
        self._bad = np.zeros(n, np.int64)
        self._bad_why = [None] * n
        self._reset_stream()
        self._land_lock = threading.Lock()
        self._collectors = []
        #: Set-points sent last: (N, 3) velocities and, for ``full_state``,
        #: the (N, 3) reference positions and (N,) yaws.
        self.last_velocity = self.last_position = self.last_yaw = None
        #: Set-points the sender put, in all.
        self.setpoints_sent = 0

    def _reset_stream(self):
        self._send_lock = threading.Lock()
        self._held = None                        # (v (N, 3), monotonic time it was set)
        self._closed = False
        self._landing = False
        self._sender = None
        self._stop_sender = threading.Event()
        self._p_ref = self._t_sent = self._yaw_sp = None
        self._hold_expired = False

    # ---------------------------------------------------------------- receive
    def _reject(self, i, why):
        with self._lock:
            self._bad[i] += 1
            if self._bad_why[i] is None:
                self._bad_why[i] = why

    def _pose_in(self, i, vals, now):
        """A decoded pose ``(x, y, z, qw, qx, qy, qz, stamp)`` of vehicle i."""
        vals = np.asarray(vals, float)
        nq = float(np.linalg.norm(vals[3:7]))
        if not np.isfinite(vals).all():
            return self._reject(i, "non-finite values")
        if not 0.5 <= nq <= 1.5:
            return self._reject(i, f"orientation quaternion of norm {nq:.3g}")
        with self._lock:
            prev = self._prev[i].copy()
            self._prev[i] = (*vals[:3], vals[7])
        dt = vals[7] - prev[3]
        vel = (vals[:3] - prev[:3]) / dt if np.isfinite(dt) and dt > 0 else np.zeros(3)
        self.telemetry.pose(i, vals[:3], vel, now=now)
        self.telemetry.attitude(i, vals[3:7] / nq)
        if not np.isfinite(self._z0[i]):
            self._z0[i] = vals[2]
        # landed: on the floor and still; or, with a status topic, its "is
        # flying" bit clear (the firmware keeps that bit 2 s after the motors
        # stop, supervisor.c IS_FLYING_HYSTERESIS_THRESHOLD: the pose is quicker)
        on_floor = bool(vals[2] < self._z0[i] + 0.03 and abs(vel[2]) < 0.05)
        self._on_floor[i] = on_floor
        if self._status_seen[i]:
            self.telemetry.armed(i, self._flying[i] or not on_floor,
                                 landed=on_floor or not self._flying[i])
        else:
            self.telemetry.armed(i, not on_floor, landed=on_floor)

    def _on_pose(self, i, data, now):
        # malformed payloads are counted and dropped (the vehicle counts as
        # silent until valid poses come); close() warns with the counts
        try:
            vals = _types.decode_pose(data)
        except Exception as e:  # noqa: BLE001 - any decoding failure is bad input
            return self._reject(i, f"not a PoseStamped ({type(e).__name__})")
        self._pose_in(i, vals, now)

    def _on_poses(self, data, now):
        """``/poses``: the motion-capture array; entries not named after one
        of our vehicles are ignored, a malformed array counts against all."""
        try:
            stamp, entries = _types.decode_named_poses(data)
        except Exception as e:  # noqa: BLE001
            why = (str(e) if len(data) > _types.MAX_POSES_BYTES
                   else f"not a NamedPoseArray ({type(e).__name__})")
            for i in range(self.n):
                self._reject(i, why)
            return
        for name, *vals in entries:
            i = self._index.get(name)
            if i is not None:
                self._pose_in(i, (*vals, stamp), now)

    def _on_status(self, i, data, now):
        try:
            m = _types.deserialize(data, _types.STATUS)
        except Exception:  # noqa: BLE001
            return
        self._status_seen[i] = True
        self._sup[i] = int(m.supervisor_info)
        self.telemetry.heard(i, now=now)
        if np.isfinite(m.battery_voltage) and m.battery_voltage > 0:
            self.telemetry.battery(i, battery_fraction(m.battery_voltage))
        flying = bool(m.supervisor_info & IS_FLYING)
        self._flying[i] = flying
        self.telemetry.armed(i, bool(m.supervisor_info & IS_ARMED) or flying,
                             landed=not flying or bool(self._on_floor[i]))

    # ---------------------------------------------------------------- FleetLink
    def open(self):
        from ._link import CfLink
        topic, ptype = SETPOINTS[self.setpoint]
        self._link = link = CfLink(self.router, domain=self.domain, node=self.node,
                                   mode=self.mode)
        self._keys = [link.key(f"/{nm}/{topic}", ptype) for nm in self.names]
        if self.exclusive:
            others = link.claim(self._keys)
            taken = [nm for nm, k in zip(self.names, self._keys) if others.get(k)]
            if taken:
                raise PreflightError(
                    f"vehicle(s) {taken} are already commanded by another avblocks "
                    f"process (via router {self.router}); nothing was sent to them",
                    block="Crazyflies", hint="stop the other run first")
        self._pubs = [link.publisher(f"/{nm}/{topic}", ptype) for nm in self.names]
        if self.pose_source == "mocap":
            link.subscribe("/poses", _types.NAMED_POSE_ARRAY, self._on_poses)
        for i, nm in enumerate(self.names):
            if self.pose_source == "pose":
                link.subscribe(f"/{nm}/pose", _types.POSE_STAMPED,
                               lambda d, now, i=i: self._on_pose(i, d, now))
            link.subscribe(f"/{nm}/status", _types.STATUS,
                           lambda d, now, i=i: self._on_status(i, d, now))
        self._takeoff = [link.client(f"/{nm}/takeoff", _types.TAKEOFF) for nm in self.names]
        self._land = [link.client(f"/{nm}/land", _types.LAND) for nm in self.names]
        self._notify = [link.client(f"/{nm}/notify_setpoints_stop", _types.NOTIFY)
                        for nm in self.names]
        self._arm = [link.client(f"/{nm}/arm", _types.ARM) for nm in self.names]
        self._reset_stream()

    # ---------------------------------------------------------------- arming
    def _arm_vehicles(self):
        """Arm the vehicles that need it (see ``arm``) and wait until each
        reports it can fly; FlightError naming the vehicle otherwise."""
        if self.arm is False:
            return
        sup = self._sup.copy()
        if self.arm == "auto":
            unknown = [nm for nm, s in zip(self.names, sup) if s < 0]
            if unknown:
                self.record("arm_unknown", vehicles=unknown,
                            note="no /cfN/status: cannot tell whether they need arming "
                                 "(arm=True arms every vehicle)")
            need = [i for i, s in enumerate(sup)
                    if s >= 0 and not s & AUTO_ARM and not s & IS_ARMED]
        else:
            need = list(range(self.n))
        if not need:
            return
        pend = [(i, self._arm[i].send(self.service_timeout, arm=True)) for i in need]
        bad = [f"{self.names[i]}: arm not acknowledged ({why})"
               for i, p in pend for ok, why in [p.wait()] if not ok]
        self.record("arm_sent", vehicles=[self.names[i] for i in need], refused=bad)
        if bad:
            raise FlightError("arming failed: " + "; ".join(bad), block="Crazyflies",
                              hint="does the Crazyswarm2 server serve /cfN/arm? (arm=False "
                                   "for a vehicle that arms itself)")
        self._armed_by_us = need
        # the supervisor goes Arming -> Ready to fly (supervisor_state_machine.c);
        # the high-level commander is blocked until then (stabilizer.c), so the
        # takeoff waits for CAN_FLY. Without a status topic: a second, as
        # Crazyswarm2's arming example waits.
        t_end = time.monotonic() + self.arm_timeout
        if not all(self._status_seen[i] for i in need):
            time.sleep(min(1.0, self.arm_timeout))
        while True:
            ready = [i for i in need if not self._status_seen[i] or self._sup[i] & CAN_FLY]
            if len(ready) == len(need):
                return
            if time.monotonic() > t_end:
                late = [f"{self.names[i]} (status bits {int(self._sup[i])})" for i in need
                        if i not in ready]
                raise FlightError("armed but not ready to fly within "
                                  f"{self.arm_timeout:g} s: " + ", ".join(late),
                                  block="Crazyflies",
                                  hint="check the vehicle's console (tumbled? a deck "
                                       "fault?)")
            time.sleep(0.02)

    def _disarm_landed(self):
        """Disarm the vehicles armed by us that are down (on the floor and
        still, by a fresh pose; or their status' flying bit clear): never one
        in the air, where disarming stops the motors. (A brushless vehicle's
        motors idle while armed; the firmware disarms it by itself 3 s after
        its flying bit clears, 2 s after touch-down.)"""
        tm = self.telemetry.snapshot()
        down = [i for i in self._armed_by_us if tm.landed[i] and tm.pose_age[i] < 1.0]
        if not down or self._link is None:
            return
        pend = [(i, self._arm[i].send(self.service_timeout, arm=False)) for i in down]
        out = {self.names[i]: p.wait(self.land_ack_wait)[1] for i, p in pend}
        self.record("disarm_sent", vehicles=[self.names[i] for i in down], replies=out)
        self._armed_by_us = [i for i in self._armed_by_us if i not in down]

    # ---------------------------------------------------------------- takeoff
    def takeoff(self, height, timeout):
        self._arm_vehicles()
        tm = self.telemetry.snapshot()
        self._z0 = np.nan_to_num(tm.position[:, 2])
        target = self._z0 + float(height)
        duration = max(1.0, float(height) / self.takeoff_speed)
        pend = [c.send(self.service_timeout, height=float(z), duration=duration)
                for c, z in zip(self._takeoff, target)]
        bad = []
        for nm, p in zip(self.names, pend):
            ok, why = p.wait()
            if not ok:
                bad.append(f"{nm}: takeoff not acknowledged ({why})")
        self.record("takeoff_sent", height=target.tolist(), duration=duration,
                    refused=bad)
        if bad:
            raise FlightError("takeoff failed: " + "; ".join(bad), block="Crazyflies",
                              hint="check that crazyflie_server runs and serves these "
                                   "vehicles")
        t_start = time.monotonic()
        deadline = t_start + max(float(timeout), duration + 1.0)
        while time.monotonic() < deadline:
            tm = self.telemetry.snapshot()
            there = (np.abs(tm.position[:, 2] - target) < 0.05) & (
                np.abs(tm.velocity[:, 2]) < 0.1)
            if time.monotonic() - t_start >= 0.9 * duration and there.all():
                return
            time.sleep(0.02)
        tm = self.telemetry.snapshot()
        low = [f"{nm}: at z={z:.2f} m, expected {zt:.2f} m" for nm, z, zt in
               zip(self.names, tm.position[:, 2], target) if not abs(z - zt) < 0.05]
        raise FlightError("takeoff did not reach its height in time: " + "; ".join(low)
                          + " (the firmware ignores a takeoff while its planner is busy, "
                            "the supervisor is locked, or the vehicle is not armed: "
                            "arm=True for a Crazyflie 2.1 Brushless without a status "
                            "topic)", block="Crazyflies")

    # ---------------------------------------------------------------- streaming
    def send_velocity(self, v):
        v = np.array(v, float)
        now = time.monotonic()
        with self._send_lock:
            if self._closed:
                return
            self._held = (v, now)
            self._hold_expired = False
            start = self._sender is None
            if start:
                self._sender = threading.Thread(target=self._stream, daemon=True,
                                                name="avblocks-cf-sender")
        if start:
            self._sender.start()

    def _put(self, v, now):
        """Put one set-point per vehicle (called with ``_send_lock`` held)."""
        stamp = time.time()
        if self.setpoint == "velocity":
            for pub, vi in zip(self._pubs, v):
                pub.put(_types.encode_velocity_world(vi, 0.0, stamp))
            self.last_velocity = v.copy()
        else:
            if self._p_ref is None:
                tm = self.telemetry.snapshot()
                self._p_ref = np.nan_to_num(tm.position).copy()
                self._yaw_sp = (quat_yaw(tm.attitude) if self.yaw is None
                                else np.array(self.yaw, float))
                self.record("stream_start", position=self._p_ref.tolist(),
                            yaw=self._yaw_sp.tolist())
            else:
                self._p_ref = self._p_ref + v * min(now - self._t_sent, 0.5)
            for pub, p, vi, yw in zip(self._pubs, self._p_ref, v, self._yaw_sp):
                pub.put(_types.encode_full_state(p, vi, (0.0, 0.0, 0.0), float(yw), stamp))
            self.last_velocity, self.last_position = v.copy(), self._p_ref.copy()
            self.last_yaw = self._yaw_sp.copy()
        self._t_sent = now
        self.setpoints_sent += 1

    def _stream(self):
        period = 1.0 / self.stream_rate
        nxt = time.monotonic()
        while True:
            with self._send_lock:
                if self._closed:
                    return
                now = time.monotonic()
                v, t_set = self._held
                if now - t_set <= self.hold:
                    try:
                        self._put(v, now)
                    except Exception as e:  # noqa: BLE001 - the session is closing
                        self.record("send_error", error=str(e))
                elif not self._hold_expired:
                    self._hold_expired = True
                    self.record("hold_expired", age=round(now - t_set, 3))
            nxt += period
            delay = nxt - time.monotonic()
            if delay < -0.5:                    # far behind (a stopped process): resync
                nxt, delay = time.monotonic(), 0.0
            if self._stop_sender.wait(max(delay, 0.0)):
                return

    def _stop_streaming(self):
        """No set-point after this returns: the sender is told to stop
        under its lock, and joined."""
        with self._send_lock:
            self._closed = True
            th = self._sender
        self._stop_sender.set()
        if th is not None and th is not threading.current_thread():
            th.join(timeout=2.0)

    # ---------------------------------------------------------------- landing
    def land(self, action="land"):
        """Stop the sender, then ``notify_setpoints_stop`` to every vehicle
        and each one's ``land`` as soon as its notification is acknowledged
        (``land_ack_wait`` at most); a thread collects the replies for the
        flight log. Any thread. Called again, it sends the pair again to the
        vehicles that did not acknowledge both (a lossy link)."""
        link = self._link
        if link is None:
            return
        with self._land_lock:
            first = not self._landing
            self._landing = True
            self._stop_streaming()
            if first:
                todo = list(range(self.n))
                self._announce_landing(link)
            else:
                prev_n, prev_l = self._pair
                todo = [i for i in range(self.n)
                        if not (prev_n[i].wait(self.land_ack_wait)[0]
                                and prev_l[i].wait(self.land_ack_wait)[0])]
                if not todo:
                    return
            try:
                pn = list(self._pair[0]) if not first else [None] * self.n
                pl = list(self._pair[1]) if not first else [None] * self.n
                for i in todo:
                    pn[i] = self._notify[i].send(self.service_timeout,
                                                 remain_valid_millisecs=100)
                    pl[i] = None
                deadline = time.monotonic() + self.land_ack_wait
                while True:
                    late = time.monotonic() >= deadline
                    for i in todo:
                        if pl[i] is None and (late or pn[i].done()):
                            pl[i] = self._land[i].send(self.service_timeout,
                                                       height=self.land_height,
                                                       duration=self.land_duration)
                    if all(pl[i] is not None for i in todo):
                        break
                    time.sleep(0.0005)
            except Exception as e:  # noqa: BLE001 - the session is closing
                self.record("land_error", error=str(e))
                return
            self._pair = (pn, pl)
        th = threading.Thread(target=self._collect, args=(todo, pn, pl), daemon=True,
                              name="avblocks-cf-land")
        self._collectors.append(th)
        th.start()

    def _announce_landing(self, link):
        """Liveliness tokens saying this session lands these vehicles now:
        the guard leaves them to it."""
        try:
            zid = str(link.session.info.zid())
            for k in self._keys:
                link._tokens.append(link.session.liveliness().declare_token(
                    f"{LANDING_PREFIX}/{k}/{zid}"))
        except Exception:  # noqa: BLE001 - the guard then lands them too: harmless
            pass

    def _collect(self, todo, pn, pl):
        out = []
        for i in todo:
            ok1, w1 = pn[i].wait()
            ok2, w2 = pl[i].wait()
            if not (ok1 and ok2):
                out.append({"vehicle": self.names[i], "notify": w1, "land": w2})
        self.record("land_sent", vehicles=[self.names[i] for i in todo],
                    order=["notify_setpoints_stop", "land"], unanswered=out)

    @property
    def malformed(self):
        """``{pose topic: payloads dropped}`` (vehicles with any)."""
        with self._lock:
            bad = self._bad.copy()
        topic = "/poses" if self.pose_source == "mocap" else None
        return {topic or f"/{nm}/pose": int(c) for nm, c in zip(self.names, bad) if c}

    def close(self):
        import warnings
        self._stop_streaming()
        with self._lock:
            bad, why = self._bad.copy(), list(self._bad_why)
        for i in np.nonzero(bad)[0]:
            topic = "/poses" if self.pose_source == "mocap" else f"/{self.names[i]}/pose"
            self.record("malformed", vehicle=self.names[i], count=int(bad[i]), first=why[i])
            warnings.warn(RobotWarning(
                f"vehicle '{self.names[i]}': {bad[i]} malformed payload(s) on "
                f"'{topic}' ignored (first: {why[i]})"), stacklevel=2)
        if self._link is not None:
            try:
                self._disarm_landed()
            except Exception as e:  # noqa: BLE001 - closing anyway
                self.record("disarm_error", error=str(e))
        # the last requests reach the server and their replies the log
        for th in self._collectors:
            th.join(timeout=self.service_timeout + 0.5)
        self._collectors = []
        link, self._link = self._link, None
        if link is not None:
            link.close()
