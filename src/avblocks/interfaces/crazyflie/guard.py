"""A guard process that lands Crazyflies whose commander stops commanding.

A Crazyflie flying on streamed set-points levels out 0.5 s after the last
one and stops its motors at 2 s (crazyflie-firmware ``supervisor.c``,
``COMMANDER_WDT_TIMEOUT_STABILIZE`` / ``_SHUTDOWN``): it falls. Nothing on
the vehicle or in Crazyswarm2 lands it. The guard is a second, small
process, run beside the Crazyswarm2 server (on the machine that has the
radio), that **watches the set-points themselves**:

* it subscribes to every vehicle's command topics (``/cfN/cmd_full_state``,
  ``/cfN/cmd_velocity_world``) on the router, and to ``/cfN/pose`` (or the
  motion-capture ``/poses``) to know whether the vehicle is up;
* when a vehicle's set-points stop for longer than ``timeout`` (0.4 s by
  default, under the firmware's 0.5 s level-out and far under its 2 s
  motor cut) while it is above the floor (``z > floor + 0.05`` m, the
  floor being the lowest height seen), it sends
  ``notify_setpoints_stop`` and then ``land``, the order Crazyswarm2
  prescribes (see :mod:`.link`). Whatever stopped the stream: a killed
  commander, a frozen one (SIGSTOP, a swapping laptop), a dropped Wi-Fi
  link between the commander's computer and the router; the guard needs
  no word from the commander, only the absence of its set-points;
* it also lands a vehicle whose commander's claim (the Zenoh liveliness
  token ``avblocks/commander/...`` by which a :class:`Crazyflies` block
  claims it) disappears while the vehicle is up, without a landing being
  announced: a commander that dies during takeoff, before any set-point;
* a commander that lands its vehicles itself announces it first (a
  liveliness token ``avblocks/landing/...``, see :mod:`.link`); the guard
  then leaves them alone.

The commander's sender streams the held set-point at its own rate (50 Hz)
whatever its diagram does, so a slow diagram step does not trip the guard;
only a process that cannot send (dead, stopped, cut off) does. A link that
stalls longer than ``timeout`` and then recovers is landed by the guard,
and the commander's next set-point takes the vehicle back (the firmware
gives streamed set-points the priority); keep ``timeout`` above the worst
gap of a healthy link.
"""

from __future__ import annotations

import json
import threading
import time

import numpy as np

from ..ros2._zenoh import CLAIM_PREFIX
from . import _types
from ._link import CfLink
from .link import LANDING_PREFIX, POSE_SOURCES, SETPOINTS

#: Default time without set-points before the guard lands a vehicle [s].
TIMEOUT = 0.4
#: After a commander vanishes (without announcing a landing) while its vehicle
#: is still on the floor, the guard lands the vehicle if it leaves the floor
#: within this time [s]: the takeoff it was given goes on without it (the
#: high-level commander's polynomial leaves the floor slowly: 5 cm of a
#: 1.5 m, 5 s takeoff take about 1.3 s).
ORPHAN_WINDOW = 5.0


class Guard:
    """Lands the Crazyflies ``names`` when their set-points stop (see the
    module docstring).

    Parameters
    ----------
    names : list of str or "cf1,cf2"
    router : str
        Zenoh router endpoint.
    timeout : float [s]
        Set-points stopped this long (while the vehicle is up): land it.
    land_duration, land_height : float
        Of the landing it commands [s, m].
    pose_source : {"pose", "mocap"}
        Where it reads the vehicles' heights (``/cfN/pose`` or ``/poses``).
    period : float [s]
        How often it checks.
    domain : int, optional
        ROS domain id.
    log : path, optional
        JSON-lines log of what it saw and did.
    """

    def __init__(self, names, router="tcp/127.0.0.1:7447", *, timeout=TIMEOUT,
                 land_duration=3.0, land_height=0.03, pose_source="pose", period=0.01,
                 domain=None, log=None):
        from ...core.errors import ParameterError
        self.names = [s.strip() for s in (names.split(",") if isinstance(names, str)
                                          else names)]
        if not self.names or any(not s for s in self.names):
            raise ParameterError("give the vehicle names", param="names", found=names)
        if not (0 < float(timeout) < 2.0):
            raise ParameterError("timeout must be in (0, 2) s: under the firmware's 2 s "
                                 "motor cut", param="timeout", found=timeout)
        if pose_source not in POSE_SOURCES:
            raise ParameterError("unknown pose source", param="pose_source",
                                 expected=list(POSE_SOURCES), found=pose_source)
        self.timeout, self.period = float(timeout), float(period)
        self.land_duration, self.land_height = float(land_duration), float(land_height)
        self._log = open(log, "a", buffering=1) if log else None
        self._lock = threading.Lock()
        n = len(self.names)
        self.z = np.full(n, np.nan)
        self.floor = np.full(n, np.inf)
        self.last_sp = np.full(n, -np.inf)      # monotonic time of the last set-point
        self.streaming = np.zeros(n, bool)      # set-points came since the last landing
        self.handled = np.zeros(n, bool)        # landed by the guard (until new set-points)
        self.owners = [set() for _ in range(n)]     # commander session ids
        # its commander announced it lands the vehicle (kept until a new stream:
        # the announcement's token goes with the commander's session)
        self.announced = np.zeros(n, bool)
        # its commander vanished while it stood on the floor (monotonic time;
        # -inf: no): a takeoff it had been given may still lift it
        self.orphaned = np.full(n, -np.inf)
        #: What the guard did: ``(vehicle, reason, age of the last set-point [s])``.
        self.landed = []
        self.link = link = CfLink(router, domain=domain, node="avblocks_guard")
        index = {nm: i for i, nm in enumerate(self.names)}
        if pose_source == "mocap":
            def on_poses(data, now):
                try:
                    _, entries = _types.decode_named_poses(data)
                except Exception:  # noqa: BLE001 - not an array, or too large: ignore
                    return
                for name, _x, _y, z, *_ in entries:
                    if name in index:
                        self._height(index[name], z)
            link.subscribe("/poses", _types.NAMED_POSE_ARRAY, on_poses)
        self._land = [link.client(f"/{nm}/land", _types.LAND) for nm in self.names]
        self._notify = [link.client(f"/{nm}/notify_setpoints_stop", _types.NOTIFY)
                        for nm in self.names]
        self._prefixes = {}
        for i, nm in enumerate(self.names):
            if pose_source == "pose":
                link.subscribe(f"/{nm}/pose", _types.POSE_STAMPED,
                               lambda d, now, i=i: self._on_pose(i, d))
            for topic, ptype in SETPOINTS.values():
                link.subscribe(f"/{nm}/{topic}", ptype,
                               lambda d, now, i=i: self._on_setpoint(i, now))
                key = link.key(f"/{nm}/{topic}", ptype)
                self._prefixes[f"{CLAIM_PREFIX}/{key}/"] = (i, "claim")
                self._prefixes[f"{LANDING_PREFIX}/{key}/"] = (i, "landing")
        self._subs = [link.session.liveliness().declare_subscriber(
            f"{prefix}/**", self._on_token, history=True)
            for prefix in (CLAIM_PREFIX, LANDING_PREFIX)]
        self._stop = threading.Event()
        self._watch = threading.Thread(target=self._watchdog, daemon=True,
                                       name="avblocks-cf-guard")
        self._watch.start()
        self.write({"ev": "start", "vehicles": self.names, "timeout": self.timeout})

    def write(self, rec):
        with self._lock:
            if self._log is not None:
                self._log.write(json.dumps({"wall": time.time(), **rec}) + "\n")

    # ---------------------------------------------------------------- inputs
    def _height(self, i, z):
        if np.isfinite(z):
            self.z[i] = z
            self.floor[i] = min(self.floor[i], z)

    def _on_pose(self, i, data):
        try:
            z = _types.decode_pose(data)[2]
        except Exception:  # noqa: BLE001 - not a pose: ignore
            return
        self._height(i, z)

    def _on_setpoint(self, i, now):
        # the payload is not decoded: its arrival is what counts
        with self._lock:
            self.last_sp[i] = now
            first = not self.streaming[i]
            self.streaming[i] = True
            self.handled[i] = False
            self.orphaned[i] = -np.inf
            if first:
                self.announced[i] = False
        if first:
            self.write({"ev": "stream", "vehicle": self.names[i]})

    def _on_token(self, sample):
        key = str(sample.key_expr)
        hit = next(((p, v) for p, v in self._prefixes.items() if key.startswith(p)), None)
        if hit is None:
            return
        prefix, (i, kind) = hit
        zid = key[len(prefix):]
        import zenoh
        put = sample.kind == zenoh.SampleKind.PUT
        nm = self.names[i]
        if kind == "landing":
            if put:
                with self._lock:
                    self.announced[i] = True
                    self.streaming[i] = False       # its commander lands it
                self.write({"ev": "commander_lands", "vehicle": nm, "session": zid})
            return
        with self._lock:
            (self.owners[i].add if put else self.owners[i].discard)(zid)
            announced = bool(self.announced[i])
            left = not self.owners[i]
            if put:
                self.orphaned[i] = -np.inf
            elif left and not announced:
                self.orphaned[i] = time.monotonic()
        if put:
            self.write({"ev": "commander", "vehicle": nm, "session": zid})
            return
        self.write({"ev": "commander_gone", "vehicle": nm, "session": zid,
                    "z": None if not np.isfinite(self.z[i]) else float(self.z[i]),
                    "flying": self._flying(i)})
        if left and not announced and self._flying(i):
            self._trigger(i, "commander gone")

    # ---------------------------------------------------------------- acting
    def _flying(self, i):
        return bool(np.isfinite(self.z[i]) and self.z[i] > self.floor[i] + 0.05)

    def _watchdog(self):
        while not self._stop.wait(self.period):
            now = time.monotonic()
            for i in range(len(self.names)):
                with self._lock:
                    due = (self.streaming[i] and now - self.last_sp[i] > self.timeout
                           and not self.announced[i])
                    orphan = (now - self.orphaned[i] < ORPHAN_WINDOW and not self.owners[i]
                              and not self.announced[i])
                if due and self._flying(i):
                    self._trigger(i, f"no set-point for more than {self.timeout:g} s")
                elif orphan and self._flying(i):
                    with self._lock:
                        self.orphaned[i] = -np.inf
                    self._trigger(i, "commander gone during its takeoff")

    def _trigger(self, i, reason):
        with self._lock:
            if self.handled[i]:
                return
            self.handled[i] = True
            self.streaming[i] = False           # until the next set-point
            age = time.monotonic() - self.last_sp[i]
        threading.Thread(target=self._land_one, args=(i, reason, age), daemon=True).start()

    def _land_one(self, i, reason, age):
        ok1, why1 = self._notify[i].send(1.0, remain_valid_millisecs=100).wait(0.3)
        ok2, why2 = self._land[i].send(1.0, height=self.land_height,
                                       duration=self.land_duration).wait()
        self.landed.append((self.names[i], reason, age))
        self.write({"ev": "landed_by_guard", "vehicle": self.names[i], "reason": reason,
                    "setpoint_age": round(age, 4) if np.isfinite(age) else None,
                    "notify": why1, "land": why2, "ok": bool(ok1 and ok2)})

    # ---------------------------------------------------------------- running
    def run(self, duration=None):
        """Guard until :meth:`stop` (or ``duration`` seconds)."""
        self._stop.wait(duration)

    def stop(self):
        self._stop.set()

    def close(self):
        self._stop.set()
        self._watch.join(timeout=1.0)
        for s in self._subs:
            try:
                s.undeclare()
            except Exception:  # noqa: BLE001 - closing anyway
                pass
        self.link.close()
        with self._lock:
            if self._log is not None:
                self._log.close()
                self._log = None


def main(args):
    """``avblocks crazyflies guard``."""
    import signal
    g = Guard(args.names, args.router, timeout=args.timeout,
              land_duration=args.land_duration, land_height=args.land_height,
              pose_source=args.pose_source, domain=args.domain, log=args.log)
    signal.signal(signal.SIGTERM, lambda *a: g.stop())
    print(f"guarding Crazyflies {','.join(g.names)} via {args.router} (land after "
          f"{g.timeout:g} s without set-points)", flush=True)
    try:
        g.run(args.duration)
    except KeyboardInterrupt:
        pass
    finally:
        g.close()
    return 0


def add_parser(rs):
    """Add ``guard`` to the ``crazyflies`` command group."""
    g = rs.add_parser("guard", help="land Crazyflies whose avblocks commander stops "
                                    "sending set-points (run beside the Crazyswarm2 "
                                    "server)")
    g.add_argument("--names", required=True, help="vehicle names, e.g. cf1,cf2,cf3")
    g.add_argument("--router", default="tcp/127.0.0.1:7447", help="Zenoh router endpoint")
    g.add_argument("--timeout", type=float, default=TIMEOUT,
                   help=f"land after this long without set-points [s] (default {TIMEOUT}; "
                        "the firmware levels out at 0.5 s and cuts the motors at 2 s)")
    g.add_argument("--land-duration", type=float, default=3.0, dest="land_duration")
    g.add_argument("--land-height", type=float, default=0.03, dest="land_height")
    g.add_argument("--pose-source", default="pose", choices=list(POSE_SOURCES),
                   dest="pose_source", help="heights from /cfN/pose or /poses (mocap)")
    g.add_argument("--domain", type=int, default=None, help="ROS domain id")
    g.add_argument("--duration", type=float, help="seconds to run (default: forever)")
    g.add_argument("--log", help="JSON-lines log")
    g.set_defaults(fn=main)
    return g
