"""Key conventions, CDR bytes and liveliness tokens of the ROS 2 link,
checked against independent truth: byte layouts written out by hand from
the CDR rules, the key formats of the rmw_zenoh design document, and
zenoh-ros2-sdk's own type-hash computation."""

from __future__ import annotations

import struct
import time

import numpy as np
import pytest

import avblocks as av

from .conftest import _need


@pytest.fixture(autouse=True)
def _deps():
    _need("zenoh")
    _need("rosbags")


def test_twist_cdr_layout_matches_the_cdr_rules():
    from avblocks.interfaces.ros2 import _msgs
    b = _msgs.encode_twist((0.25, -1.0, 0.0), (0.0, 0.5, 2.0))
    # encapsulation header CDR_LE (00 01 00 00), then six float64 little endian
    assert b == bytes([0, 1, 0, 0]) + struct.pack("<6d", 0.25, -1.0, 0.0, 0.0, 0.5, 2.0)
    assert _msgs.decode_twist(b) == ((0.25, -1.0, 0.0), (0.0, 0.5, 2.0))


def test_odometry_round_trip_rotates_body_twist_to_world():
    from avblocks.interfaces.ros2 import _msgs
    yaw = np.pi / 2
    b = _msgs.encode_odometry(1.0, 2.0, 0.5, yaw, (0.3, 0.0, 0.0), (0, 0, 0.1), 12.25)
    x, y, z, th, vx, vy, vz, stamp = _msgs.decode_odometry(b)
    assert (x, y, z, stamp) == (1.0, 2.0, 0.5, 12.25)
    assert th == pytest.approx(yaw, abs=1e-12)
    # forward 0.3 m/s while facing +y is +y in the world
    assert (vx, vy) == pytest.approx((0.0, 0.3), abs=1e-12)


def test_rmw_zenoh_keys_and_type_hash_match_an_independent_implementation(router):
    from zenoh_ros2_sdk.utils import get_type_hash

    from avblocks.interfaces.ros2 import Link, _msgs
    ts = _msgs.typestore("jazzy")
    # the SDK computes RIHS01 itself from .msg texts: give it the definitions
    deps = {"geometry_msgs/msg/Vector3": "float64 x\nfloat64 y\nfloat64 z\n"}
    sdk = get_type_hash("geometry_msgs/msg/Twist",
                        msg_definition="Vector3 linear\nVector3 angular\n",
                        dependencies=deps)
    assert sdk == _msgs.type_hash("geometry_msgs/msg/Twist") == ts.hash_rihs01(
        "geometry_msgs/msg/Twist")
    link = Link(router, "rmw_zenoh", domain=7)
    try:
        assert link.key("/tb1/cmd_vel", _msgs.TWIST) == (
            "7/tb1/cmd_vel/geometry_msgs::msg::dds_::Twist_/" + sdk)
    finally:
        link.close()
    bridge = Link(router, "bridge")
    try:
        assert bridge.key("/tb1/cmd_vel", _msgs.TWIST) == "tb1/cmd_vel"
    finally:
        bridge.close()


def test_rmw_zenoh_attachment_and_liveliness_tokens(router):
    import zenoh

    from avblocks.interfaces.ros2 import Link, _msgs, open_session
    peer = open_session(router)
    got, tokens = [], []
    link = None
    try:
        sub = peer.declare_subscriber("0/tb1/cmd_vel/**", lambda s: got.append(
            (str(s.key_expr), s.attachment.to_bytes() if s.attachment else None)))
        lv = peer.liveliness().declare_subscriber(
            "@ros2_lv/0/**", lambda s: tokens.append(str(s.key_expr)) if
            s.kind == zenoh.SampleKind.PUT else None, history=True)
        link = Link(router, "rmw_zenoh", domain=0, node="avb_test")
        pub = link.publisher("tb1/cmd_vel", _msgs.TWIST)
        time.sleep(0.3)
        for _ in range(2):
            pub.put(_msgs.encode_twist((1, 0, 0), (0, 0, 0)))
        deadline = time.monotonic() + 3
        while (len(got) < 2 or len(tokens) < 2) and time.monotonic() < deadline:
            time.sleep(0.02)
        key, att = got[-1]
        assert key.endswith("geometry_msgs::msg::dds_::Twist_/" + _msgs.type_hash(_msgs.TWIST))
        assert len(att) == 8 + 8 + 1 + 16 and att[16] == 16
        seq, stamp = struct.unpack("<qq", att[:16])
        assert seq == 2 and abs(stamp / 1e9 - time.time()) < 5
        zid = str(link.session.info.zid())
        node = [t for t in tokens if "/NN/" in t]
        pubs = [t for t in tokens if "/MP/" in t]
        assert node == [f"@ros2_lv/0/{zid}/0/0/NN/%/%/avb_test"]
        assert pubs[0].startswith(f"@ros2_lv/0/{zid}/0/1/MP/%/%/avb_test/%tb1%cmd_vel/"
                                  "geometry_msgs::msg::dds_::Twist_/RIHS01_")
        sub.undeclare()
        lv.undeclare()
    finally:
        if link is not None:
            link.close()
        peer.close()


def test_bad_arguments_are_named():
    from avblocks.interfaces.ros2 import Robots
    for kw, word in (({"kind": "tank"}, "kind"), ({"transport": "dds"}, "transport"),
                     ({"arena": (1, 0, 0, 1)}, "arena"), ({"timeout": 0.0}, "timeout"),
                     ({"mocap_transform": (1, 2)}, "mocap_transform")):
        with pytest.raises(av.AvError, match=word):
            Robots(["tb1"], **kw)
    with pytest.raises(av.AvError, match="unique"):
        Robots(["tb1", "tb1"])


def test_rclpy_transport_without_ros2_fails_cleanly_at_start():
    from avblocks.interfaces.ros2 import _rclpy, robots
    if _rclpy.available():
        pytest.skip("rclpy is installed here: the clean-failure path does not apply")
    b = robots.Robots(["tb1"], transport="rclpy")
    with pytest.raises(av.AvError, match="rclpy is not importable"):
        b.on_start()


def test_swap_checks_ports():
    from avblocks.interfaces.ros2 import Robots, replace_block, robots_like
    from avblocks.scenarios import formation
    d, _ = formation.make_diagram(followers=2, dt=0.05)
    with pytest.raises(av.AvError, match="3 vehicles but 2 robot names"):
        robots_like(d["fleet"].block, "tb1,tb2")
    with pytest.raises(av.AvError, match="cmd"):
        replace_block(d, "fleet", Robots(["a", "b", "c"], kind="holonomic2d"))
    with pytest.raises(av.AvError, match="estop"):
        replace_block(d, "fleet", Robots(["a", "b", "c"], estop=True))
    r = robots_like(d["fleet"].block, "a,b,c", v_max=0.3)
    replace_block(d, None, r)
    assert d["fleet"].block is r and r.v_max.tolist() == [0.3] * 3
    d.build()
