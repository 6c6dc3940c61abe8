"""``Crazyflies``: N Crazyflies through Crazyswarm2's ROS 2 interface over
Zenoh, as a block with the velocity-controlled quadrotor's ports."""

from __future__ import annotations

from ...core.errors import ParameterError
from ..flight import Fleet
from .link import SETPOINTS, CrazyflieLink


class Crazyflies(Fleet):
    """N Crazyflies commanded through Crazyswarm2 (rmw_zenoh), with the ports
    of :func:`~avblocks.vehicles.velocity_controlled_quadrotor`.

    Ports
    -----
    velocity : in, (N, 3) [m/s]
        World-frame velocity set-points, streamed each major step (or
        ``period``) on ``/cfN/cmd_full_state`` (default) or
        ``/cfN/cmd_velocity_world``.
    position : out, (N, 3) [m]
        From ``/cfN/pose`` (PoseStamped, world frame).
    pose : out, (N, 3) [m, m, rad]
        (x, y, yaw) of the latest pose.
    attitude : out, (N, 4)
        Unit quaternion (w, x, y, z) of the latest pose.
    fresh : out, (N,) bool
        A pose arrived within ``timeout``.
    age : out, (N,) [s]
        Time since each vehicle's latest pose.

    State
    -----
    The outputs, as discrete states updated once per major step from the
    receive buffer (see :class:`~avblocks.interfaces.flight.Fleet`).

    Parameters
    ----------
    names : list of str or "cf1,cf2"
        Vehicle names as in Crazyswarm2's ``crazyflies.yaml``, in agent order.
    router : str
        Zenoh router endpoint (``ros2 run rmw_zenoh_cpp rmw_zenohd``).
    setpoint : {"full_state", "velocity"}
        ``full_state`` (FullState: reference position integrated from the
        commanded velocities from the position at the start of the
        mission, the velocity as feed-forward; served by Crazyswarm2's C++
        server and its simulator) or ``velocity`` (VelocityWorld; the C++
        server only).
    takeoff_speed : float [m/s]
        Mean climb speed of the firmware's takeoff trajectory.
    land_duration : float [s]
        Duration of the firmware's landing trajectory.
    land_height : float [m]
        Height the landing trajectory ends at (the motors stop there).
    service_timeout : float [s]
        How long a service call waits for its reply.
    domain : int, optional
        ROS domain id (default ``$ROS_DOMAIN_ID`` or 0).
    node : str
        Node name shown by ``ros2 node list``.
    exclusive : bool
        Refuse to start when another avblocks process commands one of them.
    **flight
        The flight layer's keyword arguments (``takeoff_height``,
        ``speed_max``, ``accel_max``, ``geofence``, ``min_separation``,
        ``battery_min``, ``timeout``, ``stale_timeout``, ``link_timeout``,
        ``log``, ...; see :class:`~avblocks.interfaces.flight.Fleet`).

    Equations
    ---------
    Sent velocity ``v_i`` = the input shaped by the flight limits; with
    ``full_state`` the sent position is ``p_ref(t_k) = p_ref(t_{k-1}) +
    v_i (t_k - t_{k-1})`` (wall-clock step, at most 0.5 s), ``p_ref`` = the
    measured position at the first mission step.

    References
    ----------
    Crazyswarm2 1.0.5 (``crazyflie_interfaces``, ``crazyflie_server.cpp``);
    crazyflie-firmware 2026.08 (commander priorities, high-level commander,
    supervisor set-point watchdog); the rmw_zenoh design document.

    Examples
    --------
    >>> from avblocks.interfaces.crazyflie import Crazyflies
    >>> b = Crazyflies(["cf1", "cf2"])
    >>> sorted(b.input_ports), sorted(b.output_ports)
    (['velocity'], ['age', 'attitude', 'fresh', 'pose', 'position'])
    """

    failsafe_actions = ("land",)

    def __init__(self, names, router="tcp/127.0.0.1:7447", *, setpoint="full_state",
                 takeoff_speed=0.3, land_duration=3.0, land_height=0.0, service_timeout=1.0,
                 domain=None, node="avblocks", exclusive=True, **flight):
        if setpoint not in SETPOINTS:
            raise ParameterError("unknown set-point kind", block="Crazyflies",
                                 param="setpoint", expected=list(SETPOINTS), found=setpoint)
        for name, v in (("takeoff_speed", takeoff_speed), ("land_duration", land_duration),
                        ("service_timeout", service_timeout)):
            if not (isinstance(v, (int, float)) and v > 0 and v < float("inf")):
                raise ParameterError("must be a positive number", block="Crazyflies",
                                     param=name, found=v)
        super().__init__(names, **flight)
        self.router, self.setpoint = router, setpoint
        self.takeoff_speed, self.land_duration = float(takeoff_speed), float(land_duration)
        self.land_height, self.service_timeout = float(land_height), float(service_timeout)
        self.domain, self.node, self.exclusive = domain, node, bool(exclusive)

    def open_link(self):
        return CrazyflieLink(self.names, self.router, setpoint=self.setpoint,
                             takeoff_speed=self.takeoff_speed,
                             land_duration=self.land_duration, land_height=self.land_height,
                             service_timeout=self.service_timeout, domain=self.domain,
                             node=self.node, exclusive=self.exclusive, record=self.record)
