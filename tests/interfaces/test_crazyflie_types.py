"""Crazyswarm2's types and the helpers of the Crazyflie interface, against
independent truth: the service type hash printed in the rmw_zenoh design
document, zenoh-ros2-sdk's own RIHS01 computation, CDR byte layouts
written out by hand from the CDR rules, the firmware's battery table and
the rest-to-rest polynomial's defining conditions."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from .conftest import _need


@pytest.fixture(autouse=True)
def _deps():
    _need("rosbags")


def test_service_hash_reproduces_the_rmw_zenoh_design_document():
    from avblocks.interfaces.crazyflie import _types as T
    ts = T.new_store(T.service_types("example_interfaces/srv/AddTwoInts",
                                     "int64 a\nint64 b\n", "int64 sum\n"))
    # rmw_zenoh docs/design.md: the add_two_ints service key
    assert ts.hash_rihs01("example_interfaces/srv/AddTwoInts") == (
        "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a")


def test_crazyflie_hashes_match_zenoh_ros2_sdk():
    _need("zenoh_ros2_sdk")
    from zenoh_ros2_sdk.utils import compute_service_type_hash, get_type_hash

    from avblocks.interfaces.crazyflie import _types as T
    deps = {"builtin_interfaces/msg/Time": "int32 sec\nuint32 nanosec\n",
            "builtin_interfaces/msg/Duration": "int32 sec\nuint32 nanosec\n",
            "std_msgs/msg/Header": "builtin_interfaces/Time stamp\nstring frame_id\n",
            "geometry_msgs/msg/Vector3": "float64 x\nfloat64 y\nfloat64 z\n",
            "geometry_msgs/msg/Point": "float64 x\nfloat64 y\nfloat64 z\n",
            "geometry_msgs/msg/Quaternion": "float64 x 0\nfloat64 y 0\nfloat64 z 0\n"
                                            "float64 w 1\n",
            "geometry_msgs/msg/Pose": "Point position\nQuaternion orientation\n",
            "geometry_msgs/msg/Twist": "Vector3 linear\nVector3 angular\n"}
    defs = T.definitions()
    assert len(defs) == 11
    for name, text in defs.items():
        if "/msg/" in name:
            sdk = get_type_hash(name, msg_definition=text, dependencies=deps)
        else:
            req, resp = T.split_srv(text)
            # the SDK wants a non-empty text for an empty response; a comment is one
            sdk = compute_service_type_hash(name, req, resp or "# empty", dependencies=deps)
        assert T.type_hash(name) == sdk, name
    # PoseStamped: the same hash as in rosbags' own Jazzy store
    from avblocks.interfaces.ros2 import _msgs
    assert T.type_hash(T.POSE_STAMPED) == _msgs.type_hash(_msgs.POSE_STAMPED)


def test_rmw_zenoh_keys_of_topics_and_services(router):
    _need("zenoh")
    from avblocks.interfaces.crazyflie import _types as T
    from avblocks.interfaces.crazyflie._link import CfLink
    link = CfLink(router, domain=3)
    try:
        assert link.key("/cf2/takeoff", T.TAKEOFF) == (
            "3/cf2/takeoff/crazyflie_interfaces::srv::dds_::Takeoff_/" + T.type_hash(T.TAKEOFF))
        assert link.key("/cf2/cmd_full_state", T.FULL_STATE) == (
            "3/cf2/cmd_full_state/crazyflie_interfaces::msg::dds_::FullState_/"
            + T.type_hash(T.FULL_STATE))
    finally:
        link.close()


def test_request_cdr_layouts_by_hand():
    from avblocks.interfaces.crazyflie import _types as T
    # Takeoff: header CDR_LE, uint8 group_mask, pad to 4, float32 height, Duration
    # (int32 sec, uint32 nanosec)
    b = T.request(T.TAKEOFF, group_mask=2, height=0.75, duration=2.5)
    assert b == (bytes([0, 1, 0, 0]) + bytes([2, 0, 0, 0]) + struct.pack("<f", 0.75)
                 + struct.pack("<iI", 2, 500_000_000))
    assert T.decode_request(T.TAKEOFF, b) == {"group_mask": 2, "height": 0.75,
                                             "duration": 2.5}
    b = T.request(T.NOTIFY, remain_valid_millisecs=100)
    assert b == bytes([0, 1, 0, 0]) + bytes([0, 0, 0, 0]) + struct.pack("<I", 100)
    # the empty response: the one uint8 member ROS 2 adds
    assert T.empty_response(T.LAND) == bytes([0, 1, 0, 0, 0])


def test_velocity_world_and_full_state_cdr_by_hand():
    from avblocks.interfaces.crazyflie import _types as T
    b = T.encode_velocity_world((0.5, -0.25, 0.125), 0.0, 12.5, frame="w")
    # Header: Time (int32, uint32), string (uint32 length incl. NUL, bytes), then 2
    # bytes of padding: the float64 that follows starts at body offset 16 (a multiple
    # of 8); Vector3, float32 yaw rate
    head = struct.pack("<iI", 12, 500_000_000) + struct.pack("<I", 2) + b"w\0"
    assert b == (bytes([0, 1, 0, 0]) + head + bytes(2) + struct.pack("<3d", 0.5, -0.25, 0.125)
                 + struct.pack("<f", 0.0))
    b = T.encode_full_state((1, 2, 3), (0.1, 0.2, 0.3), (0, 0, 0), np.pi / 2, 12.5, frame="w")
    q = (0.0, 0.0, np.sin(np.pi / 4), np.cos(np.pi / 4))      # x y z w
    assert b == (bytes([0, 1, 0, 0]) + head + bytes(2) + struct.pack("<3d", 1, 2, 3)
                 + struct.pack("<4d", *q) + struct.pack("<3d", 0.1, 0.2, 0.3) + bytes(24)
                 + bytes(24))


def test_battery_fraction_follows_the_firmware_curve():
    from avblocks.interfaces.crazyflie import battery_fraction
    # crazyflie-firmware pm_stm32f4.c: 3.00 V 0 %, 3.78 V 10 %, ..., 3.92 V 50 %,
    # 4.10 V 90 %; 4.2 V full
    assert battery_fraction(3.92) == pytest.approx(0.5)
    assert battery_fraction(3.805) == pytest.approx(0.15)
    assert battery_fraction(2.9) == 0.0 and battery_fraction(4.3) == 1.0
    assert battery_fraction(4.15) == pytest.approx(0.95)


def test_smooth7_is_rest_to_rest_to_third_order():
    from avblocks.interfaces.crazyflie.emulator import smooth7
    f, df, ddf = smooth7(np.array([0.0, 0.5, 1.0]))
    assert f.tolist() == [0.0, 0.5, 1.0]
    assert df.tolist() == [0.0, 140 / 64, 0.0] and ddf.tolist() == [0.0, 0.0, 0.0]
    # the derivatives it returns are those of f (central differences)
    s, h = np.linspace(0.05, 0.95, 19), 1e-5
    _, d1, d2 = smooth7(s)
    assert np.allclose((smooth7(s + h)[0] - smooth7(s - h)[0]) / (2 * h), d1, atol=1e-6)
    assert np.allclose((smooth7(s + h)[1] - smooth7(s - h)[1]) / (2 * h), d2, atol=1e-5)
    # zero jerk at both ends: f'' grows like s^2 from each end
    e = 1e-3
    assert smooth7(np.array([e]))[2][0] / e < 1.0
    assert abs(smooth7(np.array([1 - e]))[2][0]) / e < 1.0


def test_malformed_pose_payloads_are_dropped_counted_and_warned(router):
    _need("zenoh")
    import time
    import warnings

    from avblocks.interfaces.crazyflie import CrazyflieLink
    from avblocks.interfaces.crazyflie import _types as T
    from avblocks.interfaces.crazyflie._link import CfLink
    from avblocks.interfaces.flight import RobotWarning
    link = CrazyflieLink(["cf1", "cf2"], router, exclusive=False)
    link.open()
    peer = CfLink(router, node="peer")
    try:
        pub1 = peer.publisher("/cf1/pose", T.POSE_STAMPED)
        pub2 = peer.publisher("/cf2/pose", T.POSE_STAMPED)
        time.sleep(0.5)
        good = T.encode_pose((1.0, 2.0, 0.5), (1.0, 0.0, 0.0, 0.0), 10.0)
        pub1.put(good)
        pub2.put(good[:20])                                     # truncated
        pub2.put(T.encode_pose((np.nan, 0, 0), (1, 0, 0, 0), 10.1))  # NaN
        pub2.put(T.encode_pose((0, 0, 0), (0, 0, 0, 0), 10.2))      # no rotation
        time.sleep(0.5)
        tm = link.telemetry.snapshot()
        assert tm.position[0].tolist() == [1.0, 2.0, 0.5] and tm.poses.tolist() == [1, 0]
        assert link.malformed == {"/cf2/pose": 3}
    finally:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            link.close()
        peer.close()
    (w,) = [c for c in caught if issubclass(c.category, RobotWarning)]
    assert "'cf2': 3 malformed payload(s) on '/cf2/pose'" in str(w.message)
    assert "not a PoseStamped" in str(w.message)


def test_a_poses_array_too_large_is_dropped_unread(router):
    """A NamedPoseArray of 3,000 bodies (216 kB) takes rosbags about 0.15 s to
    decode on a loaded machine, a 7 MB one 6 s, holding the commander's
    threads: over 128 KiB it is dropped unread and counted."""
    _need("zenoh")
    import time
    import warnings

    from avblocks.interfaces.crazyflie import CrazyflieLink
    from avblocks.interfaces.crazyflie import _types as T
    from avblocks.interfaces.crazyflie._link import CfLink
    link = CrazyflieLink(["cf1"], router, exclusive=False, pose_source="mocap")
    link.open()
    peer = CfLink(router, node="mocap")
    try:
        pub = peer.publisher("/poses", T.NAMED_POSE_ARRAY)
        time.sleep(0.5)
        names = ["cf1"] + [f"body{k}" for k in range(2999)]
        big = T.encode_named_poses(names, np.ones((3000, 3)), np.tile([1.0, 0, 0, 0],
                                                                       (3000, 1)), 5.0)
        assert len(big) > 128 * 1024
        pub.put(big)
        time.sleep(0.5)
        assert link.telemetry.snapshot().poses.tolist() == [0]
        assert link.malformed == {"/poses": 1}
        pub.put(T.encode_named_poses(["cf1"], [[1.0, 2.0, 0.5]], [[1.0, 0, 0, 0]], 5.1))
        time.sleep(0.5)
        tm = link.telemetry.snapshot()
        assert tm.poses.tolist() == [1] and tm.position[0].tolist() == [1.0, 2.0, 0.5]
    finally:
        with warnings.catch_warnings(record=True):
            warnings.simplefilter("always")
            link.close()
        peer.close()
