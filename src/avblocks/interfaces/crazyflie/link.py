"""The Crazyswarm2 protocol under :class:`~avblocks.interfaces.flight.Fleet`:
a :class:`~avblocks.interfaces.flight.FleetLink` speaking rmw_zenoh to a
``crazyflie_server`` (or to :mod:`.emulator`).

Per vehicle ``cfN`` (names as in Crazyswarm2's ``crazyflies.yaml``):

=========================================  =======================================
``/cfN/pose`` (PoseStamped) in             position, attitude; velocity by finite
                                           difference of the stamps
``/cfN/status`` (Status) in, optional      battery (voltage -> charge with the
                                           firmware's LiPo curve), flying bit
``/cfN/cmd_full_state`` (FullState) out    ``setpoint="full_state"``: position
                                           integrated from the commanded velocity,
                                           the velocity, zero acceleration, yaw 0
``/cfN/cmd_velocity_world`` out            ``setpoint="velocity"``: the velocity,
                                           yaw rate 0
``/cfN/takeoff`` (Takeoff) service         height = start z + takeoff height
``/cfN/land`` (Land) service               fail-safe and normal end
``/cfN/notify_setpoints_stop`` service     hands control back to the firmware's
                                           high-level commander
=========================================  =======================================

Landing order: ``land`` first, then (once it is acknowledged, 0.3 s at
most) ``notify_setpoints_stop``. The firmware plans the landing at once
(from the current state) but keeps following the streamed set-points
until the notification lowers their priority, so the handover has no
gap; the other order leaves the vehicle on the idle planner's null
set-point (motors off) until ``land`` arrives.
"""

from __future__ import annotations

import threading
import time

import numpy as np

from ..flight import FleetLink, FlightError, PreflightError, RobotWarning, TelemetryBuffer
from . import _types

#: The firmware's typical LiPo charge curve (crazyflie-firmware 2026.08,
#: ``pm_stm32f4.c``): volts at 0 %, 10 %, ... 90 % charge (100 % at 4.2 V).
LIPO_VOLTS = (3.00, 3.78, 3.83, 3.87, 3.89, 3.92, 3.96, 4.00, 4.04, 4.10, 4.20)
SETPOINTS = {"full_state": ("cmd_full_state", _types.FULL_STATE),
             "velocity": ("cmd_velocity_world", _types.VELOCITY_WORLD)}
#: Status.supervisor_info bit "is flying".
IS_FLYING = 16


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
    takeoff_speed : float [m/s]
        Mean climb speed: takeoff duration = height / takeoff_speed (1 s at least).
    land_duration : float [s]
    land_height : float [m]
        Height the landing trajectory ends at (the motors stop there).
    service_timeout : float [s]
    domain, node, mode
        ROS domain id, node name, Zenoh mode.
    exclusive : bool
        Refuse to start when another avblocks process commands one of the vehicles.
    record : callable, optional
        ``record(ev, **fields)`` of the block's flight log.
    """

    def __init__(self, names, router="tcp/127.0.0.1:7447", *, setpoint="full_state",
                 takeoff_speed=0.3, land_duration=3.0, land_height=0.0, service_timeout=1.0,
                 domain=None, node="avblocks", mode="client", exclusive=True, record=None):
        self.names = list(names)
        self.n = n = len(self.names)
        self.router, self.domain, self.node, self.mode = router, domain, node, mode
        self.setpoint = setpoint
        self.takeoff_speed = float(takeoff_speed)
        self.land_duration, self.land_height = float(land_duration), float(land_height)
        self.service_timeout = float(service_timeout)
        self.land_ack_wait = min(0.3, self.service_timeout)
        self.exclusive = bool(exclusive)
        self.record = record or (lambda ev, **kw: None)
        self.telemetry = TelemetryBuffer(n)
        self._link = None
        self._lock = threading.Lock()
        self._prev = np.full((n, 4), np.nan)     # x y z stamp of the previous pose
        self._status_seen = np.zeros(n, bool)
        self._z0 = np.zeros(n)
        self._streaming = False
        self._landing = False
        self._p_ref = None
        self._t_sent = None
        self._pending = []
        self._bad = np.zeros(n, np.int64)
        self._bad_why = [None] * n
        #: Set-points sent at the last step: (N, 3) velocities and, for
        #: ``full_state``, the (N, 3) reference positions.
        self.last_velocity = None
        self.last_position = None

    # ---------------------------------------------------------------- receive
    def _reject(self, i, why):
        with self._lock:
            self._bad[i] += 1
            if self._bad_why[i] is None:
                self._bad_why[i] = why

    def _on_pose(self, i, data, now):
        # malformed payloads are counted and dropped (the vehicle counts as
        # silent until valid poses come); close() warns with the counts
        try:
            x, y, z, qw, qx, qy, qz, stamp = _types.decode_pose(data)
        except Exception as e:  # noqa: BLE001 - any decoding failure is bad input
            return self._reject(i, f"not a PoseStamped ({type(e).__name__})")
        vals = np.array([x, y, z, qw, qx, qy, qz, stamp])
        nq = float(np.linalg.norm(vals[3:7]))
        if not np.isfinite(vals).all():
            return self._reject(i, "non-finite values")
        if not 0.5 <= nq <= 1.5:
            return self._reject(i, f"orientation quaternion of norm {nq:.3g}")
        with self._lock:
            prev = self._prev[i].copy()
            self._prev[i] = (x, y, z, stamp)
        dt = stamp - prev[3]
        vel = (vals[:3] - prev[:3]) / dt if np.isfinite(dt) and dt > 0 else np.zeros(3)
        self.telemetry.pose(i, vals[:3], vel, now=now)
        self.telemetry.attitude(i, vals[3:7] / nq)
        if not self._status_seen[i]:            # no status topic: judge by the pose
            on_floor = z < self._z0[i] + 0.03 and abs(vel[2]) < 0.05
            self.telemetry.armed(i, not on_floor, landed=on_floor)

    def _on_status(self, i, data, now):
        try:
            m = _types.deserialize(data, _types.STATUS)
        except Exception:  # noqa: BLE001
            return
        self._status_seen[i] = True
        self.telemetry.heard(i, now=now)
        if np.isfinite(m.battery_voltage) and m.battery_voltage > 0:
            self.telemetry.battery(i, battery_fraction(m.battery_voltage))
        flying = bool(m.supervisor_info & IS_FLYING)
        self.telemetry.armed(i, flying, landed=not flying)

    # ---------------------------------------------------------------- FleetLink
    def open(self):
        from ._link import CfLink
        topic, ptype = SETPOINTS[self.setpoint]
        self._link = link = CfLink(self.router, domain=self.domain, node=self.node,
                                   mode=self.mode)
        if self.exclusive:
            keys = [link.key(f"/{nm}/{topic}", ptype) for nm in self.names]
            others = link.claim(keys)
            taken = [nm for nm, k in zip(self.names, keys) if others.get(k)]
            if taken:
                raise PreflightError(
                    f"vehicle(s) {taken} are already commanded by another avblocks "
                    f"process (via router {self.router}); nothing was sent to them",
                    block="Crazyflies", hint="stop the other run first")
        self._pubs = [link.publisher(f"/{nm}/{topic}", ptype) for nm in self.names]
        for i, nm in enumerate(self.names):
            link.subscribe(f"/{nm}/pose", _types.POSE_STAMPED,
                           lambda d, now, i=i: self._on_pose(i, d, now))
            link.subscribe(f"/{nm}/status", _types.STATUS,
                           lambda d, now, i=i: self._on_status(i, d, now))
        self._takeoff = [link.client(f"/{nm}/takeoff", _types.TAKEOFF) for nm in self.names]
        self._land = [link.client(f"/{nm}/land", _types.LAND) for nm in self.names]
        self._notify = [link.client(f"/{nm}/notify_setpoints_stop", _types.NOTIFY)
                        for nm in self.names]
        self._streaming = self._landing = False
        self._p_ref = self._t_sent = None

    def _calls(self, clients, what, **fields):
        """Send one request to each vehicle now; ``[(name, ok, why)]``."""
        pend = [c.send(self.service_timeout, **fields) for c in clients]
        return [(nm, *p.wait()) for nm, p in zip(self.names, pend)]

    def takeoff(self, height, timeout):
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
                          + " (the firmware ignores a takeoff while its planner is busy "
                            "or the supervisor is locked)", block="Crazyflies")

    def send_velocity(self, v):
        if self._landing:
            return
        v = np.asarray(v, float)
        now = time.monotonic()
        stamp = time.time()
        tm = self.telemetry.snapshot()
        if self.setpoint == "velocity":
            for pub, vi in zip(self._pubs, v):
                pub.put(_types.encode_velocity_world(vi, 0.0, stamp))
            self.last_velocity, self.last_position = v.copy(), None
        else:
            if self._p_ref is None:
                self._p_ref = np.nan_to_num(tm.position).copy()
            else:
                self._p_ref = self._p_ref + v * min(now - self._t_sent, 0.5)
            for pub, p, vi in zip(self._pubs, self._p_ref, v):
                pub.put(_types.encode_full_state(p, vi, (0.0, 0.0, 0.0), 0.0, stamp))
            self.last_velocity, self.last_position = v.copy(), self._p_ref.copy()
        self._t_sent = now
        self._streaming = True

    def land(self, action="land"):
        """``land`` to every vehicle, then (once each acknowledged, or after
        ``land_ack_wait`` at most) ``notify_setpoints_stop``; a thread
        collects the remaining replies for the log."""
        link = self._link
        if link is None:
            return
        self._landing = True
        try:
            pl = [c.send(self.service_timeout, height=self.land_height,
                         duration=self.land_duration) for c in self._land]
            deadline = time.monotonic() + self.land_ack_wait
            acks = []
            for p in pl:
                acks.append(p.wait(max(0.0, deadline - time.monotonic())))
            pn = [c.send(self.service_timeout, remain_valid_millisecs=100)
                  for c in self._notify]
        except Exception as e:  # noqa: BLE001 - the session is closing
            self.record("land_error", error=str(e))
            return
        self._pending = pn

        def collect():
            out = []
            for nm, (ok1, w1), b in zip(self.names, acks, pn):
                ok2, w2 = b.wait()
                if not (ok1 and ok2):
                    out.append({"vehicle": nm, "land": w1, "notify": w2})
            self.record("land_sent", unanswered=out)
        threading.Thread(target=collect, daemon=True, name="avblocks-cf-land").start()

    @property
    def malformed(self):
        """``{pose topic: payloads dropped}`` (vehicles with any)."""
        with self._lock:
            bad = self._bad.copy()
        return {f"/{nm}/pose": int(c) for nm, c in zip(self.names, bad) if c}

    def close(self):
        import warnings
        with self._lock:
            bad, why = self._bad.copy(), list(self._bad_why)
        for i in np.nonzero(bad)[0]:
            self.record("malformed", vehicle=self.names[i], count=int(bad[i]), first=why[i])
            warnings.warn(RobotWarning(
                f"vehicle '{self.names[i]}': {bad[i]} malformed payload(s) on "
                f"'/{self.names[i]}/pose' ignored (first: {why[i]})"), stacklevel=2)
        link, self._link = self._link, None
        pend, self._pending = self._pending, []
        deadline = time.monotonic() + self.land_ack_wait
        for p in pend:                          # the last requests reach the server
            p.wait(max(0.0, deadline - time.monotonic()))
        if link is not None:
            link.close()
