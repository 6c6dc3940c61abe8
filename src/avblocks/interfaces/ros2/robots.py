"""N ROS 2 robots as one block with the ports of the model it replaces.

Design: a side-effect block whose outputs are still pure
----------------------------------------------------------
The middleware is touched in three places only, all outside solver stages:

* ``on_start``: open the Zenoh session, declare one ``cmd_vel`` publisher
  and one pose subscriber per robot, wait for a pose from every robot and
  run the pre-flight check; the received poses become the block's initial
  discrete state (so the outputs at ``t0`` are the robots' real poses).
* Zenoh's own threads: each received pose is decoded and written, under a
  lock, into a small buffer (latest pose and its monotonic receive time
  per robot). Nothing else happens there.
* ``on_major_step`` (a side effect, once per major step or control period):
  the command on the input port is checked (NaN stops everything), clipped
  to the limits, zeroed for stale or emergency-stopped robots and published.

The outputs (``pose`` or ``position``/``velocity``, ``fresh``, ``age``) are
discrete states, and ``output()`` only returns them: every solver stage of
a step sees the same values, exactly as with a zero-order hold. The one
place the purity rule is bent is :meth:`update`: it returns the next state
from the receive buffer (and the wall clock, for ``age``) instead of from
``(t, x, u)`` alone. That read happens once per major step (or control
period), before the solver stages, so the rest of the diagram sees a
piecewise-constant signal like from any discrete block.

Watchdog: a robot whose latest pose is older than ``timeout`` is flagged
(``fresh`` false), its pose output keeps the last value, and it is sent
zero velocity at every step until poses come back; then control resumes.

Bad traffic: a payload on a pose topic that is larger than ``max_payload``,
does not decode as the expected message (truncated CDR, another type, an
unknown encapsulation header) or carries a non-finite or degenerate pose is
counted and dropped in the middleware thread; it never reaches the buffer,
so a robot sending only such payloads is silent to the watchdog. The main
thread warns (:class:`RobotWarning`, naming robot and topic) the first
time a topic has one, and once more at the end of the run with the count.

Ownership: before declaring any publisher, the block declares a Zenoh
liveliness token ``avblocks/commander/<cmd key>/<session id>`` per robot
and asks the router for other sessions' tokens on the same keys; if
another avblocks process already commands one of the robots, the start is
refused (:class:`PreflightError` naming the robots) without sending
anything. Two processes starting at the same instant both refuse.

Link loss: Zenoh clients reconnect to their router by themselves, and the
subscriptions come back with it. While the router is away every robot is
stale (zero commands, which cannot arrive: the robot's own command timeout
stops it); when the router returns, poses arrive and control resumes. If
no robot is heard for ``give_up`` seconds the block commands zero once
more and ends the run with :class:`RobotLinkError` (a
:class:`~avblocks.core.errors.SimulationError` carrying the log so far).
"""

from __future__ import annotations

import threading
import time

import numpy as np

from ...core.block import Block
from ...core.errors import ParameterError, SimulationError
from ..flight import _guard
from . import _msgs
from .errors import PreflightError, RobotLinkError
from .inbox import PoseInbox

KINDS = ("unicycle", "holonomic2d", "holonomic3d")
#: Largest pose payload accepted by default [bytes] (an Odometry is ~0.7 kB).
MAX_PAYLOAD = 64 * 1024
POSES = ("odom", "mocap")
TRANSPORTS = ("bridge", "rmw_zenoh", "rclpy")


def _names(names):
    if isinstance(names, str):
        names = [s for s in names.split(",") if s.strip()]
    names = [str(s).strip().strip("/") for s in names]
    if not names:
        raise ParameterError("give at least one robot name", param="names", found=names)
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ParameterError("robot names must be unique", param="names", found=dup)
    return names


def _transform(tf):
    """(x, y, z, yaw) of the fixed mocap-to-world transform."""
    if tf is None:
        return np.zeros(4)
    a = np.asarray(tf, dtype=float).ravel()
    if a.shape == (3,):
        a = np.array([a[0], a[1], 0.0, a[2]])
    if a.shape != (4,) or not np.all(np.isfinite(a)):
        raise ParameterError("mocap_transform must be (x, y, yaw) or (x, y, z, yaw) of the "
                             "mocap frame in the world frame", param="mocap_transform",
                             found=tf)
    return a


class Robots(PoseInbox, Block):
    """N ROS 2 robots over Zenoh (or rclpy), with the ports of a model block.

    Ports (``kind="unicycle"``, replaces ``vehicles.Unicycle``)
    -----------------------------------------------------------
    cmd : in, (N, 2) [m/s, rad/s]
        Forward speed and turn rate, published as ``geometry_msgs/msg/Twist``
        (``linear.x``, ``angular.z``) on ``<name>/cmd_vel``.
    pose : out, (N, 3) [m, m, rad]
        Latest x, y, yaw of each robot in the world frame.

    Ports (``kind="holonomic2d"`` / ``"holonomic3d"``, replaces ``SingleIntegrator``)
    --------------------------------------------------------------------------
    velocity : in, (N, d) [m/s]
        World-frame velocity, rotated into the body frame by the latest
        yaw (``cmd_frame="body"``, what bases and PX4-style offboard
        bridges expect on ``cmd_vel``) or sent as is (``cmd_frame="world"``).
    position : out, (N, d) [m]; velocity : out, (N, d) [m/s]
        From the odometry (its body-frame twist rotated to the world), or
        from mocap poses (velocity by finite difference of received poses).

    Every kind also has
    -------------------
    fresh : out, (N,) bool
        A pose arrived within ``timeout``.
    age : out, (N,) [s]
        Time since each robot's latest pose (wall seconds times ``time_scale``).
    estop : in, (N,) bool, only with ``estop=True``
        True stops that robot (zero velocity) for as long as it is true.

    State
    -----
    The outputs, as discrete states updated once per major step (or per
    ``period``) from the receive buffer; see the module docstring.

    Parameters
    ----------
    names : list of str or "tb1,tb2"
        Robot namespaces, in agent order.
    kind : {"unicycle", "holonomic2d", "holonomic3d"}
    pose : {"odom", "mocap"}
        ``nav_msgs/msg/Odometry`` on ``<name>/odom``, or
        ``geometry_msgs/msg/PoseStamped`` on ``vrpn_mocap/<name>/pose``
        (override with ``pose_topic``, a format string with ``{name}``).
    transport : {"bridge", "rmw_zenoh", "rclpy"}
        Zenoh key convention (see :mod:`._zenoh`) or a ROS 2 node.
    router : str
        Zenoh router endpoint (client mode: nothing listens here).
    timeout : float [s]
        Watchdog: no pose for this long -> the robot is commanded zero.
    v_max, omega_max : float or (N,)
        Unicycle command limits [m/s, rad/s], enforced before sending.
    speed_max : float or (N,)
        Holonomic speed limit [m/s] (the velocity vector is scaled down).
    arena : (xmin, xmax, ymin, ymax), optional
        Pre-flight: every robot must be inside.
    min_distance : float [m]
        Pre-flight: no two robots closer than this.
    mocap_transform : (x, y, yaw) or (x, y, z, yaw), optional
        Pose of the mocap frame in the world frame (applied to mocap poses).
    estop : bool
        Add the ``estop`` input port.
    period : float, optional
        Control period (a multiple of the run's ``dt``); default every step.
    time_scale : float
        For emulated robots running ``time_scale`` times faster than the
        wall clock (match ``simulate(realtime=...)``); 1 for real robots.
    wait : float [s]
        How long ``on_start`` waits for the first pose of every robot.
    cmd_topic, pose_topic : str, optional
        Topic format strings (``"{name}/cmd_vel"``).
    cmd_frame : {"body", "world"}
        Holonomic kinds: frame of the sent velocity.
    domain, distro, node, mode
        ROS domain id, message set ("jazzy"/"humble"), node name, Zenoh mode.
    stop_repeats : int
        Zero commands sent when stopping (20 ms apart), for lossy links.
    max_payload : int [bytes]
        Larger pose payloads are dropped unread (counted, warned).
    give_up : float or None [s]
        No pose from any robot for this long (robot seconds) ends the run
        with :class:`RobotLinkError` after stopping every robot; None waits
        for the link forever (the watchdog still zeroes every robot).
    exclusive : bool
        Refuse to start when another avblocks process commands one of the
        robots (Zenoh transports; see the module docstring).

    Equations
    ---------
    Sent command ``c_i = 0`` if robot i is stale, emergency-stopped, or the
    run ended; else ``(clip(v_i, +-v_max), clip(omega_i, +-omega_max))``
    (unicycle) or ``u_i * min(1, speed_max / |u_i|)`` (holonomic).

    References
    ----------
    AVLib paper, Sections III.D and IV.D (robot interface blocks with the
    model's ports); REP 105 (odometry frames); the rmw_zenoh design document.

    Examples
    --------
    >>> from avblocks.interfaces.ros2 import Robots
    >>> b = Robots(["tb1", "tb2"])
    >>> sorted(b.input_ports), sorted(b.output_ports)
    (['cmd'], ['age', 'fresh', 'pose'])
    """

    side_effects = True

    def __init__(self, names, kind="unicycle", pose="odom", transport="bridge",
                 router="tcp/127.0.0.1:7447", timeout=0.5, *, v_max=1.0, omega_max=2.0,
                 speed_max=1.0, arena=None, min_distance=0.0, mocap_transform=None,
                 estop=False, period=None, time_scale=1.0, wait=5.0, cmd_topic=None,
                 pose_topic=None, cmd_frame="body", domain=None, distro="jazzy",
                 node="avblocks", mode="client", stop_repeats=3, max_payload=MAX_PAYLOAD,
                 give_up=10.0, exclusive=True):
        super().__init__()
        self.names = _names(names)
        self.n = n = len(self.names)
        for val, ok, what in ((kind, KINDS, "kind"), (pose, POSES, "pose"),
                              (transport, TRANSPORTS, "transport"),
                              (cmd_frame, ("body", "world"), "cmd_frame")):
            if val not in ok:
                raise ParameterError(f"unknown {what}", block="Robots", param=what,
                                     expected=list(ok), found=val)
        self.kind, self.pose_source, self.transport = kind, pose, transport
        self.cmd_frame = cmd_frame
        self.router, self.domain, self.distro = router, domain, distro
        self.node, self.mode = node, mode
        self.arena = None if arena is None else np.asarray(arena, float)
        if self.arena is not None and (self.arena.shape != (4,)
                                       or not (self.arena[0] < self.arena[1]
                                               and self.arena[2] < self.arena[3])):
            raise ParameterError("arena must be (xmin, xmax, ymin, ymax) with min < max",
                                 block="Robots", param="arena", found=arena)
        self.tf = _transform(mocap_transform)
        self.wait = float(wait)
        self.stop_repeats = int(stop_repeats)
        self.max_payload = int(max_payload)
        if self.max_payload < 64:
            raise ParameterError("max_payload must be at least 64 bytes", block="Robots",
                                 param="max_payload", found=max_payload)
        if give_up is not None and not (float(give_up) > 0):
            raise ParameterError("give_up must be a positive number of seconds or None",
                                 block="Robots", param="give_up", found=give_up)
        self.give_up = None if give_up is None else float(give_up)
        self.exclusive = bool(exclusive)
        self.cmd_topic = cmd_topic or "{name}/cmd_vel"
        self.pose_topic = pose_topic or ("{name}/odom" if pose == "odom"
                                         else "vrpn_mocap/{name}/pose")
        self.declare_parameter("timeout", timeout, bounds=(1e-3, None), unit="s",
                               doc="watchdog: no pose for this long -> zero command")
        self.declare_parameter("min_distance", min_distance, bounds=(0, None), unit="m",
                               doc="pre-flight: minimum distance between robots")
        self.declare_parameter("time_scale", time_scale, bounds=(1e-3, None),
                               doc="emulated time per wall second")
        self.d = 2 if kind != "holonomic3d" else 3
        if kind == "unicycle":
            self.declare_parameter("v_max", v_max, (n,), bounds=(0, None), unit="m/s",
                                   doc="forward speed limit", allow_inf=True)
            self.declare_parameter("omega_max", omega_max, (n,), bounds=(0, None),
                                   unit="rad/s", doc="turn rate limit", allow_inf=True)
            self.cmd_port = "cmd"
            self.declare_input("cmd", (n, 2), unit="m/s, rad/s", labels=("v", "omega"),
                               feedthrough=False, doc="forward speed, turn rate")
            self.declare_output("pose", (n, 3), unit="m, m, rad", labels=("x", "y", "theta"))
            self.declare_discrete_state("pose", np.zeros((n, 3)))
            self._outs = ("pose",)
        else:
            self.declare_parameter("speed_max", speed_max, (n,), bounds=(0, None),
                                   unit="m/s", doc="speed limit", allow_inf=True)
            self.cmd_port = "velocity"
            self.declare_input("velocity", (n, self.d), unit="m/s", feedthrough=False)
            self.declare_output("position", (n, self.d), unit="m")
            self.declare_output("velocity", (n, self.d), unit="m/s")
            self.declare_discrete_state("position", np.zeros((n, self.d)))
            self.declare_discrete_state("velocity", np.zeros((n, self.d)))
            self._outs = ("position", "velocity")
        self.has_estop = bool(estop)
        if self.has_estop:
            self.declare_input("estop", (n,), dtype="bool", feedthrough=False,
                               doc="true stops the robot")
        self.declare_output("fresh", (n,), dtype="bool")
        self.declare_output("age", (n,), unit="s")
        self.declare_discrete_state("fresh", np.zeros(n, bool))
        self.declare_discrete_state("age", np.zeros(n))
        self._outs = self._outs + ("fresh", "age")
        if period is not None:
            self.declare_periodic(float(period))
        # receive buffer, written by the middleware's threads
        self._lock = threading.Lock()
        self._latest = np.full((n, 8), np.nan)      # x y z yaw vx vy vz stamp
        self._recv = np.full(n, -np.inf)             # monotonic receive time
        self._count = np.zeros(n, np.int64)
        self._bad = np.zeros(n, np.int64)            # malformed payloads dropped
        self._bad_why = [None] * n                    # first reason per robot
        self._bad_warned = np.zeros(n, bool)
        self._link = None
        self._pubs = []
        self._estop_latched = False
        self._was_fresh = np.ones(n, bool)
        #: ``[(t, robot, "stale" | "fresh")]`` watchdog transitions of the last run.
        self.events = []
        #: Commands actually sent at the last control step, (N, 2) or (N, d).
        self.sent = None
        self.steps_sent = 0

    # ------------------------------------------------------------ block functions
    def output(self, t, x, u, xp):
        return {k: x[k] for k in self._outs}

    def update(self, t, x, u, xp):
        # The one impure read (see the module docstring): the latest poses
        # received by the middleware's threads become the next state.
        if self._link is None:      # not started (a dry evaluation): hold
            return {k: x[k] for k in self._outs}
        latest, age, _ = self.snapshot()
        if self._bad.any() and not self._bad_warned[self._bad > 0].all():
            self._warn_malformed()
        return self._state_from(latest, age)

    # ------------------------------------------------------------ side effects
    def _open(self):
        if self.transport == "rclpy":
            from ._rclpy import RclpyLink
            return RclpyLink(node=self.node)
        from ._zenoh import Link
        return Link(self.router, self.transport, domain=self.domain, node=self.node,
                    distro=self.distro, mode=self.mode)

    def on_start(self):
        self.events = []
        self.steps_sent = 0
        self._estop_latched = False
        self._next_send = None
        with self._lock:
            self._latest[:] = np.nan
            self._recv[:] = -np.inf
            self._count[:] = 0
            self._bad[:] = 0
            self._bad_why = [None] * self.n
        self._bad_warned[:] = False
        self._link = self._open()
        try:
            if self.exclusive:
                self._claim()
            ptype = _msgs.ODOMETRY if self.pose_source == "odom" else _msgs.POSE_STAMPED
            self._pubs = [self._link.publisher(self.cmd_topic.format(name=nm), _msgs.TWIST)
                          for nm in self.names]
            for i, nm in enumerate(self.names):
                self._link.subscribe(self.pose_topic.format(name=nm), ptype,
                                     lambda data, now, i=i: self._on_pose(i, data, now))
            _guard.register(self)
            self._preflight()
        except BaseException:
            self.on_stop()
            raise
        latest, age, _ = self.snapshot()
        for k, v in self._state_from(latest, age).items():
            self.set_initial(k, v)
        self._was_fresh[:] = True

    def _claim(self):
        """Declare this process the commander of each robot; refuse (before
        any publisher exists) if another avblocks process already is."""
        claim = getattr(self._link, "claim", None)
        if claim is None:           # rclpy: no liveliness query here
            return
        keys = [self._link.key(self.cmd_topic.format(name=nm), _msgs.TWIST)
                for nm in self.names]
        others = claim(keys)
        taken = [nm for nm, k in zip(self.names, keys) if others.get(k)]
        if taken:
            who = sorted({z for k in keys for z in others.get(k, ())})
            raise PreflightError(
                f"robot(s) {taken} are already commanded by another avblocks process "
                f"(Zenoh session(s) {', '.join(who)} via router {self.router}); "
                "nothing was sent to them", block="Robots",
                hint="stop the other run first, or command other robots")

    def _preflight(self):
        deadline = time.monotonic() + self.wait
        while True:
            latest, age, count = self.snapshot()
            missing = [nm for nm, c in zip(self.names, count) if c == 0]
            if not missing or time.monotonic() > deadline:
                break
            time.sleep(0.01)
        if missing:
            with self._lock:
                bad = {nm: (int(self._bad[i]), self._bad_why[i])
                       for i, nm in enumerate(self.names) if nm in missing and self._bad[i]}
            extra = "".join(f"; {nm} sent {c} malformed payload(s) (first: {w})"
                            for nm, (c, w) in bad.items())
            raise PreflightError(
                f"no valid pose received within {self.wait:g} s from robot(s) {missing}{extra} "
                f"(topic '{self.pose_topic.format(name=missing[0])}', "
                f"transport '{self.transport}', router {self.router})",
                block="Robots", hint="check that the robots (or the emulator) run, "
                "the names and the router address")
        xy = latest[:, :2]
        if self.arena is not None:
            x0, x1, y0, y1 = self.arena
            out = [f"{nm} at ({p[0]:.2f}, {p[1]:.2f})" for nm, p in zip(self.names, xy)
                   if not (x0 <= p[0] <= x1 and y0 <= p[1] <= y1)]
            if out:
                raise PreflightError(f"robot(s) outside the arena {self.arena.tolist()}: "
                                     + ", ".join(out), block="Robots",
                                     hint="move them in or widen 'arena'")
        dmin = float(self.min_distance)
        if dmin > 0 and self.n > 1:
            dist = np.linalg.norm(xy[:, None] - xy[None], axis=-1)
            i, j = np.nonzero(np.triu(dist < dmin, 1))
            if len(i):
                pairs = ", ".join(f"{self.names[a]}-{self.names[b]} {dist[a, b]:.2f} m"
                                  for a, b in zip(i, j))
                raise PreflightError(f"robots closer than min_distance={dmin:g} m: {pairs}",
                                     block="Robots", hint="separate them before starting")

    def emergency_stop(self):
        """Latch an emergency stop (any thread): every robot gets zero velocity
        now and at every later step of this run."""
        self._estop_latched = True
        self.stop_robots()

    def _limit(self, c):
        if self.kind == "unicycle":
            c[:, 0] = np.clip(c[:, 0], -self.v_max, self.v_max)
            c[:, 1] = np.clip(c[:, 1], -self.omega_max, self.omega_max)
        else:
            sp = np.linalg.norm(c, axis=1)
            scale = np.where(sp > self.speed_max, self.speed_max / np.maximum(sp, 1e-300), 1.0)
            c = c * scale[:, None]
        return c

    def _twists(self, c, yaw):
        """(linear (N, 3), angular (N, 3)) for commands ``c``."""
        n = self.n
        lin, ang = np.zeros((n, 3)), np.zeros((n, 3))
        if self.kind == "unicycle":
            lin[:, 0], ang[:, 2] = c[:, 0], c[:, 1]
        else:
            d = self.d
            lin[:, :d] = c
            if self.cmd_frame == "body":
                cs, sn = np.cos(yaw), np.sin(yaw)
                lin[:, 0], lin[:, 1] = cs * c[:, 0] + sn * c[:, 1], -sn * c[:, 0] + cs * c[:, 1]
        return lin, ang

    def on_major_step(self, t, x, u, y):
        if self._link is None:
            return
        if self._next_send is not None and t < self._next_send - 1e-9:
            return
        per = getattr(self.sample_time, "period", None)
        self._next_send = t + per if per else None
        c = np.array(u[self.cmd_port], dtype=float)
        bad = ~np.all(np.isfinite(c), axis=1)
        if bad.any():
            self.stop_robots()
            raise SimulationError(
                "command is NaN or infinite for robot(s) "
                f"{[nm for nm, b in zip(self.names, bad) if b]}; every robot was stopped",
                block="Robots", port=self.cmd_port, time=t)
        c = self._limit(c)
        fresh = np.asarray(y["fresh"], bool)
        if self.give_up is not None:
            age = np.asarray(y["age"], float)
            if age.size and float(age.min()) > self.give_up:
                self.stop_robots()
                raise RobotLinkError(
                    f"no pose from any robot for {float(age.min()):.3g} s (give_up="
                    f"{self.give_up:g} s): the router or the network is down; every "
                    "robot was commanded zero (their own command timeout stops them "
                    "if that cannot arrive)", block="Robots", time=t,
                    hint="check the Zenoh router and the robots' links; the log up "
                         "to now is in err.results")
        stop = ~fresh
        if self.has_estop:
            stop = stop | np.asarray(u["estop"], bool)
        if self._estop_latched:
            stop[:] = True
        c[stop] = 0.0
        for i in np.nonzero(fresh != self._was_fresh)[0]:
            self.events.append((float(t), self.names[i], "fresh" if fresh[i] else "stale"))
        self._was_fresh = fresh.copy()
        with self._lock:
            yaw = self._latest[:, 3].copy()
        lin, ang = self._twists(c, np.nan_to_num(yaw))
        self._send(lin, ang)
        self.sent = c
        self.steps_sent += 1

    def _send(self, lin, ang):
        for i, pub in enumerate(self._pubs):
            pub.put(_msgs.encode_twist(lin[i], ang[i], self.distro))

    def stop_robots(self):
        """Command zero velocity to every robot now (repeated ``stop_repeats``
        times, 20 ms apart, for lossy links). Safe from any thread."""
        if self._link is None or not self._pubs:
            return
        zero = np.zeros((self.n, 3))
        for k in range(max(1, self.stop_repeats)):
            try:
                self._send(zero, zero)
            except Exception:  # noqa: BLE001 - the session may be closing
                return
            if k + 1 < self.stop_repeats:
                time.sleep(0.02)
        self.sent = np.zeros((self.n, 2 if self.kind == "unicycle" else self.d))

    def on_stop(self):
        try:
            self.stop_robots()
        finally:
            if self._bad.any():
                self._warn_malformed(final=True)
            _guard.unregister(self)
            link, self._link, self._pubs = self._link, None, []
            if link is not None:
                link.close()
