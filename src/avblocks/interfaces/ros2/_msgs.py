"""ROS 2 messages as CDR bytes, through rosbags' typestores (no hand-written
CDR). Only the few types robots need: ``geometry_msgs/msg/Twist`` out,
``nav_msgs/msg/Odometry`` or ``geometry_msgs/msg/PoseStamped`` in.

Poses are planar or 3D: :func:`odom_to_pose` returns ``(x, y, z, yaw, vx,
vy, vz, stamp)`` with the yaw of the orientation quaternion and the twist
rotated to the world frame (Odometry's twist is in the child, i.e. body,
frame; REP 105).
"""

from __future__ import annotations

import math
from functools import cache

from ...core.errors import ParameterError

TWIST = "geometry_msgs/msg/Twist"
ODOMETRY = "nav_msgs/msg/Odometry"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"

#: ROS 2 distributions whose definitions (and type hashes) we can use.
DISTROS = ("jazzy", "humble")


@cache
def typestore(distro="jazzy"):
    """The rosbags typestore of a ROS 2 distribution (cached)."""
    try:
        from rosbags.typesys import Stores, get_typestore
    except ImportError as e:  # pragma: no cover - the [ros2] extra
        raise ParameterError("ROS 2 messages need the 'rosbags' package",
                             hint="pip install 'avblocks[ros2]'") from e
    stores = {"jazzy": Stores.ROS2_JAZZY, "humble": Stores.ROS2_HUMBLE}
    if distro not in stores:
        raise ParameterError("unknown ROS 2 distribution", param="distro",
                             expected=list(stores), found=distro)
    return get_typestore(stores[distro])


def type_hash(typename, distro="jazzy"):
    """The ``RIHS01_<sha256>`` type hash rmw_zenoh puts in key expressions."""
    ts = typestore(distro)
    if distro == "humble":
        return "TypeHashNotSupported"
    return ts.hash_rihs01(typename)


def dds_name(typename):
    """``pkg/msg/Name`` -> ``pkg::msg::dds_::Name_`` (the DDS/rmw type name)."""
    pkg, kind, name = typename.split("/")
    return f"{pkg}::{kind}::dds_::{name}_"


def _stamp(ts, t):
    sec = math.floor(t)
    return ts.types["builtin_interfaces/msg/Time"](sec=int(sec),
                                                   nanosec=int((t - sec) * 1e9))


def _header(ts, t, frame):
    return ts.types["std_msgs/msg/Header"](stamp=_stamp(ts, t), frame_id=frame)


def _vec(ts, x, y, z):
    return ts.types["geometry_msgs/msg/Vector3"](x=float(x), y=float(y), z=float(z))


def encode_twist(linear, angular, distro="jazzy") -> bytes:
    """CDR bytes of a Twist from ``linear`` (3,) and ``angular`` (3,)."""
    ts = typestore(distro)
    msg = ts.types[TWIST](linear=_vec(ts, *linear), angular=_vec(ts, *angular))
    return bytes(ts.serialize_cdr(msg, TWIST))


def decode_twist(data, distro="jazzy"):
    """``(linear (3,), angular (3,))`` from Twist CDR bytes."""
    m = typestore(distro).deserialize_cdr(bytes(data), TWIST)
    return ((m.linear.x, m.linear.y, m.linear.z),
            (m.angular.x, m.angular.y, m.angular.z))


def _quat(ts, yaw):
    return ts.types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2),
                                                    w=math.cos(yaw / 2))


def _pose(ts, x, y, z, yaw):
    point = ts.types["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=float(z))
    return ts.types["geometry_msgs/msg/Pose"](position=point, orientation=_quat(ts, yaw))


def encode_odometry(x, y, z, yaw, v_body, w_body, t, frame="odom", child="base_link",
                    distro="jazzy") -> bytes:
    """CDR bytes of an Odometry: pose in ``frame``, twist (``v_body`` (3,),
    ``w_body`` (3,)) in the body frame ``child``."""
    import numpy as np
    ts = typestore(distro)
    pwc = ts.types["geometry_msgs/msg/PoseWithCovariance"](
        pose=_pose(ts, x, y, z, yaw), covariance=np.zeros(36))
    twc = ts.types["geometry_msgs/msg/TwistWithCovariance"](
        twist=ts.types[TWIST](linear=_vec(ts, *v_body), angular=_vec(ts, *w_body)),
        covariance=np.zeros(36))
    msg = ts.types[ODOMETRY](header=_header(ts, t, frame), child_frame_id=child,
                             pose=pwc, twist=twc)
    return bytes(ts.serialize_cdr(msg, ODOMETRY))


def encode_pose_stamped(x, y, z, yaw, t, frame="world", distro="jazzy") -> bytes:
    """CDR bytes of a PoseStamped (what a motion-capture driver publishes)."""
    ts = typestore(distro)
    msg = ts.types[POSE_STAMPED](header=_header(ts, t, frame), pose=_pose(ts, x, y, z, yaw))
    return bytes(ts.serialize_cdr(msg, POSE_STAMPED))


def _yaw(q):
    """Yaw of a quaternion; NaN for a degenerate one (norm far from 1, e.g.
    all zeros), which no pose source publishes on purpose."""
    n2 = q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w
    if not 0.25 <= n2 <= 2.25:
        return float("nan")
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def decode_odometry(data, distro="jazzy"):
    """``(x, y, z, yaw, vx, vy, vz, stamp)`` from Odometry CDR bytes; the
    velocity is rotated from the body frame to the odometry frame (by yaw)."""
    m = typestore(distro).deserialize_cdr(bytes(data), ODOMETRY)
    p, q = m.pose.pose.position, m.pose.pose.orientation
    yaw = _yaw(q)
    v = m.twist.twist.linear
    c, s = math.cos(yaw), math.sin(yaw)
    stamp = m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec
    return (p.x, p.y, p.z, yaw, c * v.x - s * v.y, s * v.x + c * v.y, v.z, stamp)


def decode_pose_stamped(data, distro="jazzy"):
    """``(x, y, z, yaw, nan, nan, nan, stamp)`` from PoseStamped CDR bytes."""
    m = typestore(distro).deserialize_cdr(bytes(data), POSE_STAMPED)
    p, q = m.pose.position, m.pose.orientation
    stamp = m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec
    nan = float("nan")
    return (p.x, p.y, p.z, _yaw(q), nan, nan, nan, stamp)


def pose_problem(v, with_velocity=True):
    """What is wrong with a decoded pose ``(x, y, z, yaw, vx, vy, vz, stamp)``,
    or None: a non-finite position, yaw or stamp (or velocity, for
    odometry) makes it unusable."""
    names = ("x", "y", "z", "yaw", "vx", "vy", "vz", "stamp")
    check = (0, 1, 2, 3, 7) + ((4, 5, 6) if with_velocity else ())
    bad = [names[k] for k in check if not math.isfinite(v[k])]
    if bad:
        return "non-finite " + ", ".join(bad) + (" (or a degenerate orientation "
                                                 "quaternion)" if "yaw" in bad else "")
    return None
