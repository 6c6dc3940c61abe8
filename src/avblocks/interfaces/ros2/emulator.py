"""Robot stand-ins for tests and demos: a separate process that behaves
like a fleet of ROS 2 bases on the real middleware.

Each emulated robot subscribes to ``<name>/cmd_vel`` (Twist) and publishes
``<name>/odom`` (Odometry; or ``vrpn_mocap/<name>/pose`` PoseStamped) at
``rate`` Hz of its own time, integrating its model exactly between ticks:

* unicycle: ``(v, omega)`` from ``linear.x``, ``angular.z``; the pose moves
  along the arc of constant curvature;
* holonomic2d / holonomic3d: body-frame ``linear`` rotated by the (fixed)
  yaw, position moves in a straight line.

Like a real base it stops (zero velocity) when no command came for
``cmd_timeout`` seconds (logged as a ``timeout`` event per robot: this is
what stops the fleet when the commanding process dies without a word).
Faults to test against: ``loss`` (each message in either direction
dropped with this probability), ``latency`` + ``jitter`` (uniform extra
delay, both directions), ``noise`` (Gaussian on x, y, yaw of published
poses), ``drops`` (``{name: t}``: the robot stops publishing ``t`` seconds
of its time after the first command reached the fleet, i.e. into the run;
it still receives and logs commands) and ``corrupt``
(``{name: (t, kind)}``: from ``t`` seconds after the first command the robot
publishes a malformed payload of ``kind`` instead of each pose; kinds in
:data:`CORRUPT_KINDS`).

``time_scale`` runs the emulated world that many times faster than the
wall clock (all its times, rates and delays are in its own seconds): pair
it with ``simulate(realtime=time_scale)`` and ``Robots(time_scale=...)``.

The log (JSON lines) records every command received, with the wall clock
(``time.time()``), the robot's time and whether it was dropped, plus the
start and any drop events, so tests measure from the robot's side.
"""

from __future__ import annotations

import heapq
import json
import threading
import time

import numpy as np

from ...core.errors import ParameterError
from .._emulator import run_emulator
from . import _msgs
from ._zenoh import Link

#: Malformed pose payloads the emulator can send (``corrupt``):
#: ``truncated`` (the first half of the CDR), ``wrong_type`` (a Twist),
#: ``nan`` / ``inf`` (the message with x = NaN, yaw from a NaN quaternion /
#: y = +inf), ``huge`` (a 10 MB payload with a valid header, sent at most
#: 4 times per robot second), ``bad_header`` (an unknown encapsulation id).
CORRUPT_KINDS = ("truncated", "wrong_type", "nan", "inf", "huge", "bad_header")


def parse_corrupt(items):
    """``["tb2@1.5:nan", "tb3@0:huge"]`` -> ``{"tb2": (1.5, "nan"), "tb3": (0.0, "huge")}``."""
    out = {}
    for it in items or []:
        for part in str(it).split(","):
            if not part.strip():
                continue
            try:
                nm, rest = part.split("@", 1)
                t, kind = rest.split(":", 1)
                t = float(t.strip().rstrip("s"))
            except ValueError:
                raise ParameterError("a corruption is NAME@TIME:KIND, e.g. tb2@1.5s:nan",
                                     param="corrupt", found=part) from None
            if kind.strip() not in CORRUPT_KINDS:
                raise ParameterError("unknown corruption kind", param="corrupt",
                                     expected=list(CORRUPT_KINDS), found=kind)
            out[nm.strip()] = (t, kind.strip())
    return out


def parse_drops(items):
    """``["tb2@10", "tb3@4.5s"]`` -> ``{"tb2": 10.0, "tb3": 4.5}``."""
    out = {}
    for it in items or []:
        for part in str(it).split(","):
            if not part.strip():
                continue
            if "@" not in part:
                raise ParameterError("a drop is NAME@TIME, e.g. tb2@10s", param="drop",
                                     found=part)
            nm, t = part.split("@", 1)
            out[nm.strip()] = float(t.strip().rstrip("s"))
    return out


class Emulator:
    """A fleet of emulated robots on one Zenoh session (see module docstring)."""

    def __init__(self, names, model="unicycle", pose0=None, *, router="tcp/127.0.0.1:7447",
                 transport="bridge", pose="odom", rate=30.0, loss=0.0, latency=0.0,
                 jitter=0.0, noise=0.0, drops=None, time_scale=1.0, cmd_timeout=0.5,
                 log=None, seed=0, distro="jazzy", corrupt=None):
        self.names = [s.strip() for s in (names.split(",") if isinstance(names, str)
                                          else names)]
        n = len(self.names)
        if model not in ("unicycle", "holonomic2d", "holonomic3d"):
            raise ParameterError("unknown model", param="model",
                                 expected=["unicycle", "holonomic2d", "holonomic3d"],
                                 found=model)
        if not 0 <= loss < 1:
            raise ParameterError("loss is a probability in [0, 1)", param="loss", found=loss)
        self.model, self.pose_kind = model, pose
        p = np.zeros((n, 4)) if pose0 is None else np.array(pose0, float)
        if p.ndim != 2 or p.shape[0] != n or p.shape[1] not in (2, 3, 4):
            raise ParameterError("pose0 must be (N, 2|3|4): x, y[, yaw] or x, y, z, yaw",
                                 param="pose0", found=p.shape)
        if p.shape[1] == 2:
            p = np.column_stack([p, np.zeros(n), np.zeros(n)])
        elif p.shape[1] == 3:
            p = np.column_stack([p[:, :2], np.zeros(n), p[:, 2]])
        self.state = p                          # x y z yaw
        self.cmd = np.zeros((n, 6))             # body linear (3), angular (3)
        self.last_cmd = np.full(n, -np.inf)     # robot time of the last applied command
        self.rate, self.loss, self.latency, self.jitter = rate, loss, latency, jitter
        self.noise, self.scale, self.cmd_timeout = noise, float(time_scale), cmd_timeout
        self.drops = dict(drops or {})
        unknown = set(self.drops) - set(self.names)
        if unknown:
            raise ParameterError("drop names a robot that is not emulated", param="drop",
                                 expected=self.names, found=sorted(unknown))
        self.corrupt = dict(corrupt or {})
        unknown = set(self.corrupt) - set(self.names)
        if unknown:
            raise ParameterError("corrupt names a robot that is not emulated",
                                 param="corrupt", expected=self.names, found=sorted(unknown))
        self._last_huge = {}
        self.timed_out = np.zeros(n, bool)
        self.rng = np.random.default_rng(seed)
        self.distro = distro
        self._lock = threading.Lock()
        self._pending = []                      # heap of (due wall, seq, kind, i, data)
        self._seq = 0
        self._log = open(log, "a", buffering=1) if log else None
        self.link = Link(router, transport, node="robot_emulator", distro=distro)
        ptopic = "{}/odom" if pose == "odom" else "vrpn_mocap/{}/pose"
        ptype = _msgs.ODOMETRY if pose == "odom" else _msgs.POSE_STAMPED
        self.pubs = [self.link.publisher(ptopic.format(nm), ptype) for nm in self.names]
        for i, nm in enumerate(self.names):
            self.link.subscribe(f"{nm}/cmd_vel", _msgs.TWIST,
                                lambda data, now, i=i: self._on_cmd(i, data))
        self._stop = threading.Event()
        self.wall0 = time.monotonic()
        self.dropped = set()
        self.t_first_cmd = None
        self.write({"ev": "start", "robots": self.names, "time_scale": self.scale})

    # ------------------------------------------------------------------ helpers
    def now(self):
        """Robot time [s] since start."""
        return (time.monotonic() - self.wall0) * self.scale

    def write(self, rec):
        if self._log is not None:
            rec = {"wall": time.time(), "t": round(self.now(), 6), **rec}
            with self._lock:
                self._log.write(json.dumps(rec) + "\n")

    def _delay(self):
        d = self.latency + (self.rng.uniform(0, self.jitter) if self.jitter else 0.0)
        return d / self.scale

    def _on_cmd(self, i, data):
        lin, ang = _msgs.decode_twist(data, self.distro)
        if self.t_first_cmd is None:
            self.t_first_cmd = self.now()
        lost = bool(self.loss and self.rng.random() < self.loss)
        self.write({"ev": "cmd", "robot": self.names[i], "v": lin[0], "vy": lin[1],
                    "vz": lin[2], "w": ang[2], "lost": lost})
        if lost:
            return
        with self._lock:
            self._seq += 1
            heapq.heappush(self._pending, (time.monotonic() + self._delay(), self._seq,
                                           "cmd", i, np.r_[lin, ang]))

    # ------------------------------------------------------------------ loop
    def _integrate(self, h):
        x, y, z, th = self.state.T
        c = self.cmd
        if self.model == "unicycle":
            v, w = c[:, 0], c[:, 5]
            small = np.abs(w * h) < 1e-9
            ws = np.where(small, 1.0, w)
            dx = np.where(small, v * h * np.cos(th + w * h / 2),
                          v / ws * (np.sin(th + w * h) - np.sin(th)))
            dy = np.where(small, v * h * np.sin(th + w * h / 2),
                          -v / ws * (np.cos(th + w * h) - np.cos(th)))
            th2 = np.arctan2(np.sin(th + w * h), np.cos(th + w * h))
            self.state = np.column_stack([x + dx, y + dy, z, th2])
        else:
            cs, sn = np.cos(th), np.sin(th)
            vx = cs * c[:, 0] - sn * c[:, 1]
            vy = sn * c[:, 0] + cs * c[:, 1]
            vz = c[:, 2] if self.model == "holonomic3d" else 0.0
            self.state = np.column_stack([x + vx * h, y + vy * h, z + vz * h, th])

    def _deliver(self, wall):
        with self._lock:
            due = []
            while self._pending and self._pending[0][0] <= wall:
                due.append(heapq.heappop(self._pending))
        t = self.now()
        for _, _, kind, i, data in due:
            if kind == "cmd":
                self.cmd[i] = data
                self.last_cmd[i] = t
            else:
                self.pubs[i].put(data)

    def _publish(self, t):
        n = len(self.names)
        p = self.state + (self.rng.normal(0, self.noise, (n, 4)) * [1, 1, 0, 1]
                          if self.noise else 0.0)
        for i, nm in enumerate(self.names):
            if (nm in self.drops and self.t_first_cmd is not None
                    and t - self.t_first_cmd >= self.drops[nm]):
                if nm not in self.dropped:
                    self.dropped.add(nm)
                    self.write({"ev": "drop", "robot": nm})
                continue
            if self.loss and self.rng.random() < self.loss:
                continue
            x, y, z, th = p[i]
            if (nm in self.corrupt and self.t_first_cmd is not None
                    and t - self.t_first_cmd >= self.corrupt[nm][0]):
                data = self._malformed(i, nm, x, y, z, th, t)
                if data is not None:
                    self.pubs[i].put(data)
                continue
            if self.pose_kind == "odom":
                data = _msgs.encode_odometry(x, y, z, th, self.cmd[i, :3], self.cmd[i, 3:], t,
                                             child=f"{nm}/base_link", distro=self.distro)
            else:
                data = _msgs.encode_pose_stamped(x, y, z, th, t, distro=self.distro)
            d = self._delay()
            if d <= 0:
                self.pubs[i].put(data)
            else:
                with self._lock:
                    self._seq += 1
                    heapq.heappush(self._pending, (time.monotonic() + d, self._seq,
                                                   "pose", i, data))

    def _malformed(self, i, nm, x, y, z, th, t):
        """The malformed payload robot ``i`` sends now (None: skip this tick)."""
        kind = self.corrupt[nm][1]
        if nm not in self._last_huge:
            self._last_huge[nm] = -np.inf
            self.write({"ev": "corrupt", "robot": nm, "kind": kind})
        odom = self.pose_kind == "odom"

        def enc(x=x, y=y, yaw=th):
            if odom:
                return _msgs.encode_odometry(x, y, z, yaw, self.cmd[i, :3], self.cmd[i, 3:],
                                             t, child=f"{nm}/base_link", distro=self.distro)
            return _msgs.encode_pose_stamped(x, y, z, yaw, t, distro=self.distro)
        if kind == "truncated":
            good = enc()
            return good[:len(good) // 2]
        if kind == "wrong_type":
            return _msgs.encode_twist(self.cmd[i, :3], self.cmd[i, 3:], self.distro)
        if kind == "nan":
            return enc(x=float("nan"), yaw=float("nan"))
        if kind == "inf":
            return enc(y=float("inf"))
        if kind == "bad_header":
            return b"\x07\x07\x00\x00" + enc()[4:]
        # huge: a valid header and message, then 10 MB of padding
        if t - self._last_huge[nm] < 0.25:
            return None
        self._last_huge[nm] = t
        return enc() + bytes(10 * 1024 * 1024)

    def run(self, duration=None):
        """Run until ``stop()`` or ``duration`` wall seconds."""
        period = 1.0 / (self.rate * self.scale)
        t_prev = self.now()
        nxt = time.monotonic()
        end = None if duration is None else time.monotonic() + duration
        while not self._stop.is_set() and (end is None or time.monotonic() < end):
            wall = time.monotonic()
            self._deliver(wall)
            t = self.now()
            stale = (t - self.last_cmd) > self.cmd_timeout
            for i in np.nonzero(stale & ~self.timed_out & np.isfinite(self.last_cmd))[0]:
                self.write({"ev": "timeout", "robot": self.names[i],
                            "last_cmd": float(self.last_cmd[i])})
            self.timed_out = stale
            self.cmd[stale] = 0.0
            self._integrate(t - t_prev)
            t_prev = t
            self._publish(t)
            nxt += period
            time.sleep(max(0.0, nxt - time.monotonic()))
        self.write({"ev": "end", "poses": self.state.tolist()})

    def stop(self):
        self._stop.set()

    def close(self):
        self.link.close()
        if self._log is not None:
            self._log.close()
            self._log = None


def read_log(path):
    """The emulator's JSON-lines log as a list of dicts."""
    with open(path) as f:
        return [json.loads(line) for line in f if line.strip()]


def main(args):
    """``avblocks robots emulate`` (see :func:`add_parser`)."""
    pose0 = json.loads(args.pose0) if args.pose0 else None
    if pose0 is None and args.spacing:
        n = len(args.names.split(","))
        pose0 = [[0.0, -args.spacing * k, 0.0] for k in range(n)]
    em = Emulator(args.names, args.model, pose0, router=args.router,
                  transport=args.transport, pose=args.pose, rate=args.rate, loss=args.loss,
                  latency=args.latency, jitter=args.jitter, noise=args.noise,
                  drops=parse_drops(args.drop), time_scale=args.time_scale,
                  cmd_timeout=args.cmd_timeout, log=args.log, seed=args.seed,
                  corrupt=parse_corrupt(args.corrupt))
    banner = (f"emulating {','.join(em.names)} ({args.model}, {args.transport}) via "
              f"{args.router}")
    return run_emulator(em, banner, args.duration)


def add_parser(sub):
    """Add ``robots emulate`` to the ``avblocks`` command's subparsers."""
    r = sub.add_parser("robots", help="robot tools (emulate ROS 2 robots over Zenoh)")
    rs = r.add_subparsers(dest="robots_command", required=True)
    e = rs.add_parser("emulate", help="emulate ROS 2 robots (cmd_vel in, odometry out)")
    e.add_argument("--names", required=True, help="robot namespaces, e.g. tb1,tb2,tb3")
    e.add_argument("--model", default="unicycle",
                   choices=["unicycle", "holonomic2d", "holonomic3d"])
    e.add_argument("--pose", default="odom", choices=["odom", "mocap"])
    e.add_argument("--transport", default="bridge", choices=["bridge", "rmw_zenoh"])
    e.add_argument("--router", default="tcp/127.0.0.1:7447")
    e.add_argument("--pose0", help="JSON list of [x, y, yaw] per robot")
    e.add_argument("--spacing", type=float, default=1.0,
                   help="without --pose0: robots on a line this far apart [m]")
    e.add_argument("--rate", type=float, default=30.0, help="pose rate [Hz]")
    e.add_argument("--loss", type=float, default=0.0, help="drop probability per message")
    e.add_argument("--latency", type=float, default=0.0, help="one-way delay [s]")
    e.add_argument("--jitter", type=float, default=0.0, help="extra uniform delay [s]")
    e.add_argument("--noise", type=float, default=0.0, help="pose noise std [m, rad]")
    e.add_argument("--drop", action="append", metavar="NAME@T",
                   help="robot NAME goes silent T s after the first command, e.g. tb2@10s")
    e.add_argument("--corrupt", action="append", metavar="NAME@T:KIND",
                   help="robot NAME sends malformed pose payloads of KIND from T s after "
                        f"the first command ({', '.join(CORRUPT_KINDS)}), e.g. tb2@1s:nan")
    e.add_argument("--time-scale", type=float, default=1.0, dest="time_scale",
                   help="emulated seconds per wall second")
    e.add_argument("--cmd-timeout", type=float, default=0.5, dest="cmd_timeout",
                   help="stop a robot without commands for this long [s]")
    e.add_argument("--duration", type=float, help="wall seconds to run (default: forever)")
    e.add_argument("--log", help="JSON-lines log of received commands")
    e.add_argument("--seed", type=int, default=0)
    e.set_defaults(fn=main)
    ro = rs.add_parser("router", help="run a Zenoh router (when no zenohd or bridge runs)")
    ro.add_argument("--listen", default="tcp/127.0.0.1:7447", help="endpoint to listen on")
    ro.set_defaults(fn=run_router)
    return r


def run_router(args):
    """``avblocks robots router``: a Zenoh router until Ctrl-C or SIGTERM."""
    import signal

    from ._zenoh import open_router
    session, ep = open_router(args.listen)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *a: stop.set())
    print(f"Zenoh router listening on {ep}", flush=True)
    try:
        stop.wait()
    except KeyboardInterrupt:
        pass
    finally:
        session.close()
    return 0
