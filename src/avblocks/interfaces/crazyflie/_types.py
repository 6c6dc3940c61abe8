"""Crazyswarm2's message and service types, registered with rosbags from
their ``.msg`` / ``.srv`` definitions, and the RIHS01 type hashes rmw_zenoh
puts in its key expressions.

The definitions in ``msg/`` and ``srv/`` are those of the
``crazyflie_interfaces`` package of Crazyswarm2 1.0.5 (commit
``9c722a9857617c68dba63c94a91e1cc2aef4601e``, MIT licence; unchanged up to
commit ``f6154e2d51791a41e6f320c1ee166f782be02a20`` of 2026-07-20):
messages FullState, Hover, Position, VelocityWorld, Status; services Takeoff,
Land, GoTo, NotifySetpointsStop, Arm, Stop. The motion-capture input
``/poses`` (``motion_capture_tracking_interfaces/msg/NamedPoseArray`` and
``NamedPose``) comes from ``mocap/``: the files of IMRCLab's
motion_capture_tracking (commit ``35adc3e1b10ca879d8dbcc62d1dab93819705f1d``,
MIT licence), which Crazyswarm2's server subscribes to. Each file is
byte-identical to its upstream copy (``tests/interfaces/
test_crazyflie_wire.py`` checks their SHA-256 against the upstream files').

Type hashes (REP 2016, RIHS01) are computed by rosbags from the type
descriptions. A service ``pkg/srv/Name`` is hashed as ROS 2 does: a type
with three fields ``request_message``, ``response_message`` and
``event_message`` (``Name_Event``: ``service_msgs/msg/ServiceEventInfo
info``, ``Name_Request[<=1] request``, ``Name_Response[<=1] response``).
``ServiceEventInfo.client_gid`` is ``char[16]`` in its ``.msg`` file, but
rosidl turns ``char`` into ``uint8`` before the hash is taken, so the
store here declares it ``uint8[16]`` (with ``char`` the hash of
``example_interfaces/srv/AddTwoInts`` differs from the one printed in the
rmw_zenoh design document; with ``uint8`` it is that one, which the tests
check). All types live in one private rosbags store (rosbags' own ROS 2
stores keep ``char``), seeded with the Jazzy definitions the Crazyflie
types use.
"""

from __future__ import annotations

import math
from functools import cache
from pathlib import Path

from ...core.errors import ParameterError

PKG = "crazyflie_interfaces"
HERE = Path(__file__).resolve().parent
#: Upstream version and commit the definitions match.
UPSTREAM = ("crazyswarm2", "1.0.5", "9c722a9857617c68dba63c94a91e1cc2aef4601e")

FULL_STATE = f"{PKG}/msg/FullState"
VELOCITY_WORLD = f"{PKG}/msg/VelocityWorld"
POSITION = f"{PKG}/msg/Position"
HOVER = f"{PKG}/msg/Hover"
STATUS = f"{PKG}/msg/Status"
TAKEOFF = f"{PKG}/srv/Takeoff"
LAND = f"{PKG}/srv/Land"
GO_TO = f"{PKG}/srv/GoTo"
NOTIFY = f"{PKG}/srv/NotifySetpointsStop"
ARM = f"{PKG}/srv/Arm"
STOP = f"{PKG}/srv/Stop"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
MOCAP_PKG = "motion_capture_tracking_interfaces"
NAMED_POSE = f"{MOCAP_PKG}/msg/NamedPose"
NAMED_POSE_ARRAY = f"{MOCAP_PKG}/msg/NamedPoseArray"
#: Upstream of the ``mocap/`` definitions.
MOCAP_UPSTREAM = ("motion_capture_tracking", "35adc3e1b10ca879d8dbcc62d1dab93819705f1d")

MESSAGES = ("FullState", "Hover", "Position", "VelocityWorld", "Status")
MOCAP_MESSAGES = ("NamedPose", "NamedPoseArray")
SERVICES = ("Takeoff", "Land", "GoTo", "NotifySetpointsStop", "Arm", "Stop")
_SEI = "service_msgs/msg/ServiceEventInfo"
_SEI_DEF = ("uint8 event_type\nbuiltin_interfaces/Time stamp\nuint8[16] client_gid\n"
            "int64 sequence_number\n")
# Jazzy types the Crazyflie definitions (and PoseStamped) reference.
_BASE = ("builtin_interfaces/msg/Time", "builtin_interfaces/msg/Duration",
         "std_msgs/msg/Header", "geometry_msgs/msg/Point", "geometry_msgs/msg/Quaternion",
         "geometry_msgs/msg/Pose", "geometry_msgs/msg/Vector3", "geometry_msgs/msg/Twist",
         "geometry_msgs/msg/PoseStamped")


def _rosbags():
    try:
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore
        from rosbags.typesys.base import Nodetype
    except ImportError as e:  # pragma: no cover - the [ros2] extra
        raise ParameterError("Crazyflie messages need the 'rosbags' package",
                             hint="pip install 'avblocks[ros2]'") from e
    return Stores, get_typestore, get_types_from_msg, Nodetype


def _srv_name(name):
    # rosbags files service parts under pkg/srv/msg/Name_Request; ROS 2 (and
    # the hash) call them pkg/srv/Name_Request
    return name.replace("/srv/msg/", "/srv/")


def _fix(fielddef, nodetype):
    consts, fields = fielddef

    def fix_type(t):
        kind, rest = t
        if kind == nodetype.NAME:
            return (kind, _srv_name(rest))
        if kind in (nodetype.ARRAY, nodetype.SEQUENCE):
            return (kind, (fix_type(rest[0]), rest[1]))
        return t
    return (consts, [(n, fix_type(t)) for n, t in fields])


def parse(text, name):
    """``{type name: rosbags field definition}`` of one ``.msg`` text."""
    _, _, get_types_from_msg, nodetype = _rosbags()
    return {_srv_name(k): _fix(v, nodetype)
            for k, v in get_types_from_msg(text, name).items()}


def service_types(name, request, response):
    """Field definitions of service ``name`` (``pkg/srv/Name``) from its
    request and response texts: ``Name_Request``, ``Name_Response``,
    ``Name_Event`` and the service type itself (hashed as ROS 2 does)."""
    req, resp, ev = f"{name}_Request", f"{name}_Response", f"{name}_Event"
    out = {}
    out.update(parse(request, req))
    out.update(parse(response, resp))
    out.update(parse(f"service_msgs/ServiceEventInfo info\n{req}[<=1] request\n"
                     f"{resp}[<=1] response\n", ev))
    out.update(parse(f"{req} request_message\n{resp} response_message\n"
                     f"{ev} event_message\n", name))
    return out


def split_srv(text):
    """``(request, response)`` texts of a ``.srv`` definition."""
    if "\n---" not in "\n" + text:
        raise ParameterError("a .srv definition needs a '---' line", found=text[:60])
    req, resp = ("\n" + text).split("\n---", 1)
    return req.strip() + "\n", resp.split("\n", 1)[1] if "\n" in resp else ""


def new_store(extra=None):
    """A rosbags store with the Jazzy base types, ``ServiceEventInfo`` as
    rosidl hashes it and ``extra`` field definitions."""
    stores, get_typestore, _, _ = _rosbags()
    jazzy = get_typestore(stores.ROS2_JAZZY)
    ts = get_typestore(stores.EMPTY)
    base = {k: jazzy.fielddefs[k] for k in _BASE}
    base.update(parse(_SEI_DEF, _SEI))
    ts.register(base)
    if extra:
        ts.register(extra)
    return ts


@cache
def definitions():
    """``{type name: definition text}`` of the bundled files (``.srv`` keyed
    by service name)."""
    out = {}
    for nm in MESSAGES:
        out[f"{PKG}/msg/{nm}"] = (HERE / "msg" / f"{nm}.msg").read_text()
    for nm in SERVICES:
        out[f"{PKG}/srv/{nm}"] = (HERE / "srv" / f"{nm}.srv").read_text()
    return out


@cache
def mocap_definitions():
    """``{type name: definition text}`` of the bundled motion-capture files."""
    return {f"{MOCAP_PKG}/msg/{nm}": (HERE / "mocap" / f"{nm}.msg").read_text()
            for nm in MOCAP_MESSAGES}


@cache
def typestore():
    """The private store holding every Crazyflie type (cached)."""
    extra = {}
    for name, text in definitions().items():
        if "/msg/" in name:
            extra.update(parse(text, name))
        else:
            extra.update(service_types(name, *split_srv(text)))
    for name, text in mocap_definitions().items():
        extra.update(parse(text, name))
    return new_store(extra)


@cache
def type_hash(typename):
    """``RIHS01_<sha256>`` of a message or service type."""
    return typestore().hash_rihs01(typename)


def dds_name(typename):
    """``pkg/srv/Name`` -> ``pkg::srv::dds_::Name_`` (messages alike)."""
    pkg, kind, name = typename.split("/")
    return f"{pkg}::{kind}::dds_::{name}_"


# ------------------------------------------------------------------ CDR
def _t(name):
    return typestore().types[name]


def _ser(msg, name):
    return bytes(typestore().serialize_cdr(msg, name))


def deserialize(data, name):
    """The rosbags message object of CDR ``data``."""
    return typestore().deserialize_cdr(bytes(data), name)


def _time(t):
    sec = math.floor(t)
    return _t("builtin_interfaces/msg/Time")(sec=int(sec), nanosec=int((t - sec) * 1e9))


def _duration(d):
    sec = math.floor(d)
    return _t("builtin_interfaces/msg/Duration")(sec=int(sec),
                                                  nanosec=int(round((d - sec) * 1e9)))


def _header(t, frame="world"):
    return _t("std_msgs/msg/Header")(stamp=_time(t), frame_id=frame)


def _vec3(v):
    return _t("geometry_msgs/msg/Vector3")(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def _quat_yaw(yaw):
    return _t("geometry_msgs/msg/Quaternion")(x=0.0, y=0.0, z=math.sin(yaw / 2),
                                              w=math.cos(yaw / 2))


def encode_velocity_world(vel, yaw_rate, t, frame="world") -> bytes:
    """CDR of a VelocityWorld: world-frame velocity (3,) [m/s], yaw rate [rad/s]."""
    return _ser(_t(VELOCITY_WORLD)(header=_header(t, frame), vel=_vec3(vel),
                                   yaw_rate=float(yaw_rate)), VELOCITY_WORLD)


def encode_full_state(pos, vel, acc, yaw, t, frame="world") -> bytes:
    """CDR of a FullState: position, velocity, acceleration (3,) each and a
    yaw (the orientation quaternion); body rates zero."""
    pose = _t("geometry_msgs/msg/Pose")(
        position=_t("geometry_msgs/msg/Point")(x=float(pos[0]), y=float(pos[1]),
                                               z=float(pos[2])),
        orientation=_quat_yaw(yaw))
    twist = _t("geometry_msgs/msg/Twist")(linear=_vec3(vel), angular=_vec3((0, 0, 0)))
    return _ser(_t(FULL_STATE)(header=_header(t, frame), pose=pose, twist=twist,
                               acc=_vec3(acc)), FULL_STATE)


def encode_pose(pos, quat_wxyz, t, frame="world") -> bytes:
    """CDR of a PoseStamped (what Crazyswarm2 publishes on ``/cfN/pose``)."""
    w, x, y, z = (float(c) for c in quat_wxyz)
    pose = _t("geometry_msgs/msg/Pose")(
        position=_t("geometry_msgs/msg/Point")(x=float(pos[0]), y=float(pos[1]),
                                               z=float(pos[2])),
        orientation=_t("geometry_msgs/msg/Quaternion")(x=x, y=y, z=z, w=w))
    return _ser(_t(POSE_STAMPED)(header=_header(t, frame), pose=pose), POSE_STAMPED)


def decode_pose(data):
    """``(x, y, z, qw, qx, qy, qz, stamp)`` of PoseStamped CDR bytes."""
    m = deserialize(data, POSE_STAMPED)
    p, q = m.pose.position, m.pose.orientation
    return (p.x, p.y, p.z, q.w, q.x, q.y, q.z,
            m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec)


def encode_named_poses(names, positions, quats_wxyz, t, frame="world") -> bytes:
    """CDR of a NamedPoseArray (what motion_capture_tracking publishes on
    ``/poses``): one ``NamedPose`` per name."""
    poses = []
    for nm, p, q in zip(names, positions, quats_wxyz):
        w, x, y, z = (float(c) for c in q)
        poses.append(_t(NAMED_POSE)(name=str(nm), pose=_t("geometry_msgs/msg/Pose")(
            position=_t("geometry_msgs/msg/Point")(x=float(p[0]), y=float(p[1]),
                                                   z=float(p[2])),
            orientation=_t("geometry_msgs/msg/Quaternion")(x=x, y=y, z=z, w=w))))
    return _ser(_t(NAMED_POSE_ARRAY)(header=_header(t, frame), poses=poses),
                NAMED_POSE_ARRAY)


#: Largest ``/poses`` payload decoded [bytes]: about 1,800 named bodies
#: (rosbags decodes ~4,000 entries in 0.2 s on a loaded 2-core machine, and
#: a 7 MB array took 6 s, holding the commander's threads the while).
MAX_POSES_BYTES = 128 * 1024


def decode_named_poses(data):
    """``(stamp, [(name, x, y, z, qw, qx, qy, qz)])`` of NamedPoseArray CDR;
    ValueError for a payload over :data:`MAX_POSES_BYTES` (not decoded)."""
    if len(data) > MAX_POSES_BYTES:
        raise ValueError(f"a NamedPoseArray of {len(data)} bytes (over {MAX_POSES_BYTES})")
    m = deserialize(data, NAMED_POSE_ARRAY)
    out = []
    for e in m.poses:
        p, q = e.pose.position, e.pose.orientation
        out.append((e.name, p.x, p.y, p.z, q.w, q.x, q.y, q.z))
    return m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec, out


def encode_status(t, battery_voltage, supervisor_info=0, pm_state=0) -> bytes:
    """CDR of a Status (battery voltage [V], supervisor bits)."""
    return _ser(_t(STATUS)(header=_header(t), supervisor_info=int(supervisor_info),
                           battery_voltage=float(battery_voltage), pm_state=int(pm_state),
                           rssi=0, num_rx_broadcast=0, num_tx_broadcast=0,
                           num_rx_unicast=0, num_tx_unicast=0, latency_unicast=0), STATUS)


def request(service, **fields) -> bytes:
    """CDR of a request of ``service`` (e.g. :data:`TAKEOFF`); a ``duration``
    field is given in seconds, ``group_mask`` defaults to 0 (all groups)."""
    if "duration" in fields:
        fields["duration"] = _duration(float(fields["duration"]))
    if "goal" in fields:
        g = fields["goal"]
        fields["goal"] = _t("geometry_msgs/msg/Point")(x=float(g[0]), y=float(g[1]),
                                                       z=float(g[2]))
    name = f"{service}_Request"
    cls = _t(name)
    if "group_mask" in cls.__dataclass_fields__:
        fields.setdefault("group_mask", 0)      # 0: every group
    if "arm" in fields:
        fields["arm"] = bool(fields["arm"])
    return _ser(cls(**fields), name)


def empty_response(service) -> bytes:
    """CDR of the (empty) response of ``service``."""
    name = f"{service}_Response"
    return _ser(_t(name)(structure_needs_at_least_one_member=0), name)


def decode_request(service, data):
    """The request of ``service`` as a dict (durations in seconds)."""
    m = deserialize(data, f"{service}_Request")
    out = {}
    for k in type(m).__dataclass_fields__:
        if k.startswith("__"):
            continue
        v = getattr(m, k)
        if k == "duration":
            v = v.sec + 1e-9 * v.nanosec
        elif k == "goal":
            v = (v.x, v.y, v.z)
        out[k] = v
    return out
