"""Flying drones from a diagram: the protocol-free flight layer.

The protocol packages (``interfaces.mavlink``, ``interfaces.crazyflie``)
build on this one; nothing here speaks a protocol.

Writing a protocol's block
--------------------------
Subclass :class:`Fleet` (the block: ports, phases, limits, fail-safe, log)
and implement a :class:`FleetLink` (the protocol)::

    class MyLink(FleetLink):
        def __init__(self, names, ...):
            self.telemetry = TelemetryBuffer(len(names))
        def open(self): ...               # connect; threads fill self.telemetry
        def takeoff(self, height, timeout): ...   # blocking; FlightError on refusal
        def send_velocity(self, v): ...   # (N, 3) world ENU [m/s]
        def land(self, action="land"): ...        # any thread, never blocks long
        def close(self): ...

    class MyDrones(Fleet):
        def __init__(self, names, ..., **flight):
            super().__init__(names, **flight)     # shared keyword arguments
        def open_link(self):
            return MyLink(self.names, ...)

Threads write into the :class:`TelemetryBuffer` (world frame: ENU, x east,
y north, z up; attitude a unit quaternion (w, x, y, z) body FLU -> world):
``heard(i)`` for anything received, ``pose(i, position, velocity)``,
``attitude(i, q)``, ``battery(i, fraction)``, ``armed(i, armed, landed)``,
``status(i, text)``.

What :class:`Fleet` does with it
--------------------------------
Ports: ``velocity`` in (N, 3); ``position`` (N, 3), ``pose`` (N, 3: x, y,
yaw), ``attitude`` (N, 4), ``fresh`` (N,), ``age`` (N,) out: the ports of
``vehicles.velocity_controlled_quadrotor`` plus ``fresh``/``age`` (as the
ground robots have), discrete states updated once per major step.

Phases (:data:`PHASES`, logged): ``preflight`` (``on_start``: every
vehicle answers, reports a pose younger than ``stale_timeout``, battery
at least ``battery_min`` where reported, inside the geofence, no two
closer than ``min_separation``; with ``slots`` (the scenario's start
positions) the vehicles are matched to them by where they stand
(``scipy.optimize.linear_sum_assignment`` on the (x, y) distances), agent
k flown by the vehicle on slot k, one further than ``slot_tolerance``
refused; else :class:`PreflightError` naming each vehicle and its reason,
nothing commanded) -> ``takeoff`` (``link.takeoff``) -> ``mission`` (the
diagram runs; each major step the command is checked and shaped by
:class:`FlightLimits`, then sent) -> ``land`` (``on_stop`` at the normal
end: ``link.land()`` and wait up to ``land_wait`` for every vehicle to
report landed, each confirmation logged) -> ``landed``. The link always
sees its own vehicle order (``names``); :attr:`Fleet.order` maps agents
to it.

Fail-safe (``failsafe`` phase): on a NaN or infinite command, a pose older
than ``stale_timeout``, a vehicle silent for ``link_timeout``, or a limit
broken in flight (outside the geofence by ``fence_margin``, too close),
:meth:`Fleet.land_all` calls ``link.land(failsafe)`` FIRST and the run
ends with :class:`FailsafeError` (a ``SimulationError``: the CLI saves
the results), naming every vehicle concerned (those without a fresh
pose too: links that die together die a few ms apart); ``on_stop`` then
waits up to ``land_wait`` for the vehicles still heard to report landed
and logs each (``landed``, ``land_unconfirmed``, ``land_timeout``).
On SIGINT/SIGTERM the shared signal guard (``_guard``, also used by
``interfaces.ros2``) lands every registered fleet before the
interrupt reaches the simulator; ``atexit`` does too; a watchdog thread
lands the fleet if no command step came for ``stall_timeout``;
``on_stop`` commands the landing again whatever ended the run. A killed
process (SIGKILL) sends nothing: the vehicles' own set-point timeout
(configured on the vehicle) must land them. The JSON-lines log
(``log=``) is flushed at each event.

``--robots KEY``: :mod:`.cli` maps a keyword to a protocol module
(:data:`~.cli.FLEETS`, one entry per protocol).
"""

from ._guard import register, unregister  # noqa: F401  (the signal guard's hooks)
from .errors import (  # noqa: F401  (the robot errors: documented with interfaces.ros2)
    FailsafeError,
    FlightError,
    LimitError,
    PreflightError,
    RobotError,
    RobotLinkError,
    RobotWarning,
)
from .fleet import PHASES, Fleet, FleetLink, fleet_names, quat_yaw
from .limits import FlightLimits
from .swap import find_flyer, replace_block  # noqa: F401  (documented with ros2)
from .telemetry import Telemetry, TelemetryBuffer

# PreflightError, RobotError, RobotLinkError, RobotWarning are importable
# from here too; they are documented with interfaces.ros2, which exports them.
__all__ = ["Fleet", "FleetLink", "FlightLimits", "Telemetry", "TelemetryBuffer",
           "PHASES", "FailsafeError", "FlightError", "LimitError", "fleet_names",
           "quat_yaw", "find_flyer"]
