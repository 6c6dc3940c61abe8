"""``Crazyflies``: N Crazyflies through Crazyswarm2's ROS 2 interface over
Zenoh, as a block with the velocity-controlled quadrotor's ports."""

from __future__ import annotations

import numpy as np

from ...core.errors import ParameterError
from ..flight import Fleet
from .link import POSE_SOURCES, SETPOINTS, CrazyflieLink


class Crazyflies(Fleet):
    """N Crazyflies commanded through Crazyswarm2 (rmw_zenoh), with the ports
    of :func:`~avblocks.vehicles.velocity_controlled_quadrotor`.

    Ports
    -----
    velocity : in, (N, 3) [m/s]
        World-frame velocity set-points, taken each major step (or
        ``period``) and streamed at ``stream_rate`` on
        ``/cfN/cmd_full_state`` (default) or ``/cfN/cmd_velocity_world``.
    position : out, (N, 3) [m]
        From ``/cfN/pose`` (PoseStamped, world frame) or, with
        ``pose_source="mocap"``, from ``/poses`` (NamedPoseArray).
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
    stream_rate : float [Hz]
        Rate at which one sender thread streams the held set-point (a
        slow diagram step does not interrupt the stream).
    hold : float [s]
        The sender stops repeating a set-point older than this (a hung
        diagram; the stall watchdog, ``stall_timeout``, lands first).
    yaw : None, float or (N,) [rad]
        Yaw of the full-state set-points; None (default) holds each
        vehicle's yaw at the first mission step.
    arm : {"auto", True, False}
        Call ``/cfN/arm`` before takeoff: "auto" (default) for the vehicles
        whose status reports they need it (not armed and not auto-arming:
        Crazyflie 2.1 Brushless, Bolt); True for every vehicle; False never.
        Vehicles armed here are disarmed once they report landed.
    arm_timeout : float [s]
        How long an armed vehicle may take to report it can fly.
    pose_source : {"pose", "mocap"}
        Read positions from ``/cfN/pose`` (the onboard estimate) or from the
        motion-capture array ``/poses`` (the entry named like the vehicle).
    takeoff_speed : float [m/s]
        Mean climb speed of the firmware's takeoff trajectory.
    land_duration : float [s]
        Duration of the firmware's landing trajectory.
    land_height : float [m]
        Height the landing trajectory ends at (the motors stop there);
        0.03 m as in Crazyswarm2's examples.
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
    Sent velocity ``v_i`` = the input shaped by the flight limits (held
    between steps); with ``full_state`` the sent position is ``p_ref(t_k)
    = p_ref(t_{k-1}) + v_i (t_k - t_{k-1})`` at each sent set-point ``k``
    (wall-clock step, at most 0.5 s), ``p_ref`` = the measured position at
    the first mission step, and the yaw is held.

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
                 stream_rate=50.0, hold=1.5, yaw=None, arm="auto", arm_timeout=3.0,
                 pose_source="pose", takeoff_speed=0.3, land_duration=3.0,
                 land_height=0.03, service_timeout=1.0, domain=None, node="avblocks",
                 exclusive=True, **flight):
        blk = "Crazyflies"
        if setpoint not in SETPOINTS:
            raise ParameterError("unknown set-point kind", block=blk,
                                 param="setpoint", expected=list(SETPOINTS), found=setpoint)
        if pose_source not in POSE_SOURCES:
            raise ParameterError("unknown pose source", block=blk, param="pose_source",
                                 expected=list(POSE_SOURCES), found=pose_source)
        if arm not in ("auto", True, False):
            raise ParameterError("arm is 'auto', True or False", block=blk, param="arm",
                                 found=arm)
        for name, v in (("takeoff_speed", takeoff_speed), ("land_duration", land_duration),
                        ("service_timeout", service_timeout), ("stream_rate", stream_rate),
                        ("hold", hold), ("arm_timeout", arm_timeout)):
            if not (isinstance(v, (int, float)) and v > 0 and v < float("inf")):
                raise ParameterError("must be a positive number", block=blk,
                                     param=name, found=v)
        if not (isinstance(land_height, (int, float)) and 0 <= land_height < 1):
            raise ParameterError("land_height is a height in [0, 1) m", block=blk,
                                 param="land_height", found=land_height)
        super().__init__(names, **flight)
        if yaw is not None:
            y = np.asarray(yaw, float)
            if y.shape not in ((), (self.n,)) or not np.isfinite(y).all():
                raise ParameterError("yaw is None, a number or one per vehicle [rad]",
                                     block=blk, param="yaw", found=yaw)
        self.router, self.setpoint = router, setpoint
        self.stream_rate, self.hold, self.yaw = float(stream_rate), float(hold), yaw
        self.arm, self.arm_timeout, self.pose_source = arm, float(arm_timeout), pose_source
        self.takeoff_speed, self.land_duration = float(takeoff_speed), float(land_duration)
        self.land_height, self.service_timeout = float(land_height), float(service_timeout)
        self.domain, self.node, self.exclusive = domain, node, bool(exclusive)

    def open_link(self):
        return CrazyflieLink(self.names, self.router, setpoint=self.setpoint,
                             stream_rate=self.stream_rate, hold=self.hold, yaw=self.yaw,
                             arm=self.arm, arm_timeout=self.arm_timeout,
                             pose_source=self.pose_source, takeoff_speed=self.takeoff_speed,
                             land_duration=self.land_duration, land_height=self.land_height,
                             service_timeout=self.service_timeout, domain=self.domain,
                             node=self.node, exclusive=self.exclusive, record=self.record)
