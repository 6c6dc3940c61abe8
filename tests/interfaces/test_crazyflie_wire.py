"""What the Crazyflies block puts on the wire, decoded by parsers we did not
write, and what it reads from an independent publisher.

* The interface definitions bundled with the package are byte-identical
  to Crazyswarm2's and motion_capture_tracking's (SHA-256 of the upstream
  files, recorded below from the fetched repositories).
* A tap, a separate Zenoh session of this test (plain eclipse-zenoh, no
  avblocks code), takes the block's set-points and service requests off
  the router; rosbags decodes them from those .msg/.srv texts. Truth: the
  order Crazyswarm2 prescribes (``crazyflie_py/crazyflie.py``,
  ``notifySetpointsStop``: after the last low-level set-point, before any
  high-level command), arming before takeoff for a vehicle that needs it
  (crazyflie-firmware ``supervisor.c``), the land height of Crazyswarm2's
  examples, and the vehicle's own yaw held.
* ``/poses`` from a motion-capture stand-in written with zenoh-ros2-sdk
  (its own type hash and CDR encoder, a subprocess) is read as the
  vehicles' poses.
* A service reply awaited by two threads at once reaches both (one NaN
  run had logged a notify as "no reply" that the emulator had answered).
"""

from __future__ import annotations

import hashlib
import json
import math
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import avblocks as av

from ._cf import cf_emulator, events, wait_for
from .conftest import _need, env

PKG = Path(av.__file__).resolve().parent / "interfaces" / "crazyflie"
#: SHA-256 of the upstream files: crazyflie_interfaces of IMRCLab/crazyswarm2 at
#: f6154e2d51791a41e6f320c1ee166f782be02a20 (2026-07-20), and
#: motion_capture_tracking_interfaces of IMRCLab/motion_capture_tracking at
#: 35adc3e1b10ca879d8dbcc62d1dab93819705f1d; computed with `git show
#: <commit>:<path> | sha256sum` on clones of those repositories.
UPSTREAM_SHA256 = {
    "msg/FullState.msg": "20fd4e33fe6c26d4809e14faba390768d8365d3ec5c5594a72ec67feb14e5f7f",
    "msg/Hover.msg": "520192d5ab46f3ffbedb26b88d8f08dfc49cfb1a58e76ee72c3a01af30eb854e",
    "msg/Position.msg": "d43f29a067bc6f172ea16a83b540937e6a2a1c3223ab38a79321e0ad3b590b17",
    "msg/Status.msg": "3bac2b83d7b94cbb2c7c55dc72b6bed3687fe3ce288d3f4089cd181c1289061a",
    "msg/VelocityWorld.msg": "5dbdb6ebfae8df567690d7b875613e32aaacb30ee1d98a9176a54224561423b0",
    "srv/Arm.srv": "239f9f5a53602b81d75b1e43912840720fb769f10353cb0158d5e565b9d642a0",
    "srv/GoTo.srv": "65b438f6a09e86c91bcb028fb7b16bd6803a06c57f008e2ce06840fafb5396f4",
    "srv/Land.srv": "e3b9c43bd7a3e7d1dde2381f817277b333de5c2f71c6647921ee94c32f471d5d",
    "srv/NotifySetpointsStop.srv":
        "3b4a4df3265a6df22e85427632e0f2562a75fc7d605a703cf09173e27a7d1c5d",
    "srv/Stop.srv": "40e8db5b6d24f1d943625df72d59ee2d7fafbaf53156c01eaed28dde1dd1effe",
    "srv/Takeoff.srv": "e3b9c43bd7a3e7d1dde2381f817277b333de5c2f71c6647921ee94c32f471d5d",
    "mocap/NamedPose.msg": "fab1231fe48fac7fa0f50130fc42c34605ace35cd68d232cae34529d4babe3f7",
    "mocap/NamedPoseArray.msg":
        "672c1f036b7ec1a739bdc03ae2804cfed2a0fd9230c0b960d769f72d9110fec3",
}
NAMES = ("cf1", "cf2")
YAW0 = (0.7, -1.2)
SRV_TYPES = {"arm": "Arm", "takeoff": "Takeoff", "notify_setpoints_stop": "NotifySetpointsStop",
             "land": "Land"}
SERVICES = tuple(SRV_TYPES)


def test_bundled_definitions_are_byte_identical_to_upstream():
    files = sorted(str(p.relative_to(PKG)) for p in PKG.glob("*/*.*")
                   if p.suffix in (".msg", ".srv"))
    assert files == sorted(UPSTREAM_SHA256)
    for rel, digest in UPSTREAM_SHA256.items():
        assert hashlib.sha256((PKG / rel).read_bytes()).hexdigest() == digest, rel


def _rosbags_store():
    """rosbags' own Jazzy store plus the Crazyflie types parsed by rosbags from
    the (upstream-identical) files; a service's request is the part above its
    '---' line."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore
    ts = get_typestore(Stores.ROS2_JAZZY)
    types = {}
    for name in ("FullState", "VelocityWorld"):
        types.update(get_types_from_msg((PKG / "msg" / f"{name}.msg").read_text(),
                                        f"crazyflie_interfaces/msg/{name}"))
    for name in ("Arm", "Takeoff", "Land", "NotifySetpointsStop"):
        req = (PKG / "srv" / f"{name}.srv").read_text().split("\n---")[0]
        types.update(get_types_from_msg(req, f"crazyflie_interfaces/msg/{name}_Request"))
    ts.register(types)
    return ts


class Tap:
    """A plain Zenoh session on the router that records every set-point put
    on ``*/cfN/cmd_*`` and every service request to ``*/cfN/<service>`` (as a
    complete queryable that never answers: the emulator's reply is the one the
    block gets), in the order they arrive."""

    def __init__(self, router):
        import zenoh
        c = zenoh.Config()
        c.insert_json5("mode", '"client"')
        c.insert_json5("connect/endpoints", json.dumps([router]))
        c.insert_json5("scouting/multicast/enabled", "false")
        self.session = zenoh.open(c)
        self.got = []
        self._lock = threading.Lock()
        self._handles = []
        for nm in NAMES:
            for topic in ("cmd_full_state", "cmd_velocity_world"):
                self._handles.append(self.session.declare_subscriber(
                    f"*/{nm}/{topic}/**", lambda s, nm=nm, topic=topic: self._add(
                        nm, topic, s.payload.to_bytes())))
            for srv in SERVICES:
                self._handles.append(self.session.declare_queryable(
                    f"*/{nm}/{srv}/**", lambda q, nm=nm, srv=srv: self._add(
                        nm, srv, q.payload.to_bytes()), complete=True))

    def _add(self, nm, what, payload):
        with self._lock:
            self.got.append((time.time(), nm, what, payload))

    def close(self):
        for h in self._handles:
            h.undeclare()
        self.session.close()


def _yaw(q):
    return math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))


def test_the_wire_decoded_by_rosbags_arm_takeoff_setpoints_notify_land(router, tmp_path):
    """A Crazyflie 2.1 Brushless pair (the emulator with ``--arming required``)
    started at yaws 0.7 and -1.2 rad, flown 1 s by the block with its defaults."""
    _need("rosbags")
    from avblocks.interfaces.crazyflie import Crazyflies
    ts = _rosbags_store()
    tap = Tap(router)
    try:
        with cf_emulator(router, ",".join(NAMES), tmp_path, "--position0",
                         "[[0, 0, 0], [0, 1, 0]]", "--arming", "required", "--yaw0",
                         json.dumps(YAW0)) as log:
            d = av.Diagram()
            c = d.add(av.blocks.Constant(np.array([[0.1, 0.0, 0.0], [0.0, 0.1, 0.0]])),
                      name="c")
            f = d.add(Crazyflies(list(NAMES), router, takeoff_height=0.4,
                                 land_duration=1.0, log=str(tmp_path / "flight.jsonl")),
                      name="fleet")
            d.connect(c.y, f.velocity)
            res = av.simulate(d, t_final=1.0, dt=0.05, realtime=1.0,
                              log=["fleet.pose"], progress=False)
            recs = wait_for(log, lambda r: len(events(r, "disarmed")) == 2, timeout=10)
            time.sleep(0.2)
    finally:
        tap.close()
    flight = [json.loads(s) for s in (tmp_path / "flight.jsonl").read_text().splitlines()]
    for k, nm in enumerate(NAMES):
        seq = [(w, p) for _, n, w, p in tap.got if n == nm]
        kinds = [w for w, _ in seq]
        srv = [w for w in kinds if w in SERVICES]
        assert srv == ["arm", "takeoff", "notify_setpoints_stop", "land", "arm"], srv
        first_sp = kinds.index("cmd_full_state")
        i_notify, i_land = kinds.index("notify_setpoints_stop"), kinds.index("land")
        # arm, takeoff, then the stream; the last set-point, then the notification,
        # then the landing: nothing streamed after the notification. The tap's
        # subscriber and queryable callbacks run on Zenoh's threads, so two messages
        # a millisecond apart may be appended out of order on a loaded machine (CI saw
        # the last set-point one place after the notification): each set-point's own
        # stamp (the sender's clock when it was put) must precede the notification's
        # arrival, and nothing may come after the landing.
        assert kinds.index("arm") < kinds.index("takeoff") < first_sp
        assert i_notify < i_land
        (t_notify,) = [t for t, n, w, _ in tap.got if n == nm and w == "notify_setpoints_stop"]
        stamps = [(m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec)
                  for m in (ts.deserialize_cdr(p, "crazyflie_interfaces/msg/FullState")
                            for w, p in seq if w == "cmd_full_state")]
        assert max(stamps) < t_notify, (max(stamps), t_notify)
        assert "cmd_full_state" not in kinds[i_land:]
        assert "cmd_velocity_world" not in kinds
        dec = {w: ts.deserialize_cdr(p, f"crazyflie_interfaces/msg/{SRV_TYPES[w]}_Request")
               for w, p in seq if w in ("takeoff", "land", "notify_setpoints_stop")}
        arms = [ts.deserialize_cdr(p, "crazyflie_interfaces/msg/Arm_Request").arm
                for w, p in seq if w == "arm"]
        assert arms == [True, False]            # armed for the flight, disarmed on the floor
        assert dec["takeoff"].height == pytest.approx(0.4, abs=1e-6)
        assert dec["land"].height == np.float32(0.03) and dec["land"].group_mask == 0
        assert dec["land"].duration.sec == 1 and dec["land"].duration.nanosec == 0
        assert dec["notify_setpoints_stop"].remain_valid_millisecs == 100
        sps = [ts.deserialize_cdr(p, "crazyflie_interfaces/msg/FullState")
               for w, p in seq if w == "cmd_full_state"]
        v = [[m.twist.linear.x, m.twist.linear.y, m.twist.linear.z] for m in sps]
        assert v == [[0.1, 0.0, 0.0] if k == 0 else [0.0, 0.1, 0.0]] * len(sps)
        # the yaw held is the vehicle's own (its start yaw, kept through the takeoff)
        yaws = [_yaw(m.pose.orientation) for m in sps]
        assert max(yaws) - min(yaws) < 1e-12 and yaws[0] == pytest.approx(YAW0[k], abs=0.02)
        # and the vehicle kept it: no turn to yaw 0 at the first set-point
        assert np.abs(res["fleet.pose"][:, k, 2] - YAW0[k]).max() < 0.03
    # the emulated firmware: armed by request, landed on its trajectory, no
    # landing cancelled by a late set-point
    assert [e["vehicle"] for e in events(recs, "armed")] in (list(NAMES), list(NAMES)[::-1])
    assert events(recs, "landing_cancelled") == [] and events(recs, "wdt_level_out") == []
    (arm,) = [r for r in flight if r["ev"] == "arm_sent"]
    assert arm["vehicles"] == list(NAMES) and arm["refused"] == []


def _mocap_peer(router, tmp_path):
    host, port = router.split("/", 1)[1].rsplit(":", 1)
    out = tmp_path / "mocap.jsonl"
    p = subprocess.Popen([sys.executable, str(Path(__file__).with_name("_cf_mocap_peer.py")),
                          host, port, str(tmp_path / "msgs"), str(out)],
                         env={**env(), "ZENOH_ROS2_SDK_CACHE": str(tmp_path / "cache")},
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    line = p.stdout.readline().strip()
    if line != "ready":
        p.kill()
        raise AssertionError(f"mocap peer did not start: {line} {p.stdout.read()}")
    return p, out


def test_poses_from_motion_capture_published_by_zenoh_ros2_sdk(router, tmp_path):
    _need("zenoh_ros2_sdk")
    from avblocks.interfaces.crazyflie import CrazyflieLink
    p, out = _mocap_peer(router, tmp_path)
    link = CrazyflieLink(["cf1", "cf2"], router, pose_source="mocap", exclusive=False)
    try:
        link.open()
        time.sleep(1.5)
        tm = link.telemetry.snapshot()
    finally:
        link.close()
        p.terminate()
        p.wait(10)
    sent = [json.loads(s) for s in out.read_text().splitlines()]
    assert tm.poses.min() >= 25                 # 50 Hz for 1.5 s, a loaded machine
    assert tm.pose_age.max() < 0.2
    # the latest positions are ones the peer published (float64 end to end) ...
    cf1 = {tuple(s["bodies"][0][1]) for s in sent}
    assert tuple(tm.position[0]) in cf1
    assert tm.position[1].tolist() == [1.0, 2.0, 0.05]
    # ... the velocity from the stamps' differences, the yaw from the quaternion
    assert tm.velocity[0] == pytest.approx([0.2, 0.0, 0.0], abs=0.02)
    assert tm.velocity[1] == pytest.approx([0.0, 0.0, 0.0], abs=1e-9)
    from avblocks.interfaces.flight import quat_yaw
    assert quat_yaw(tm.attitude).tolist() == pytest.approx([0.0, 0.5], abs=1e-9)
    assert link.malformed == {}


def test_a_reply_awaited_by_two_threads_reaches_both(router):
    """The land-and-notify collector and close() used to read one reply channel
    together; the one that lost the race logged "no reply"."""
    from avblocks.interfaces.crazyflie import _types as T
    from avblocks.interfaces.crazyflie._link import CfLink
    srv, cli = CfLink(router, node="server"), CfLink(router, node="client")
    try:
        srv.serve("/cf1/notify_setpoints_stop", T.NOTIFY, lambda req: time.sleep(0.2))
        time.sleep(0.5)
        pending = cli.client("/cf1/notify_setpoints_stop", T.NOTIFY).send(
            2.0, remain_valid_millisecs=100)
        got = {}
        th = [threading.Thread(target=lambda k=k, t=t: got.__setitem__(k, pending.wait(t)))
              for k, t in (("blocking", None), ("bounded", 1.5))]
        for t in th:
            t.start()
        for t in th:
            t.join(5)
    finally:
        cli.close()
        srv.close()
    assert got == {"blocking": (True, None), "bounded": (True, None)}


def test_a_reply_without_the_rmw_zenoh_attachment_or_for_another_request_is_no_answer(
        router):
    """Anyone on the router can answer a query: a reply counts only with the
    rmw_zenoh attachment carrying the request's sequence number and client
    GID (a forged "land accepted" must not stand for the server's)."""
    import zenoh

    from avblocks.interfaces.crazyflie import _types as T
    from avblocks.interfaces.crazyflie._link import CfLink, attachment
    cli = CfLink(router, node="client")
    forger = zenoh.open(zenoh.Config.from_json5(json.dumps(
        {"mode": "client", "connect": {"endpoints": [router]}})))
    try:
        client = cli.client("/cf1/land", T.LAND)
        replies = []

        def forge(query):
            kind = ("bare", "stranger")[len(replies)]
            replies.append(kind)
            if kind == "bare":
                query.reply(query.key_expr, T.empty_response(T.LAND))
            else:
                query.reply(query.key_expr, T.empty_response(T.LAND),
                            attachment=attachment(999, bytes(16)))
        q = forger.declare_queryable(client.key, forge, complete=True)
        time.sleep(0.5)
        bare = client.send(1.0, height=0.03, duration=2.0).wait()
        stranger = client.send(1.0, height=0.03, duration=2.0).wait()
        q.undeclare()
    finally:
        cli.close()
        forger.close()
    assert replies == ["bare", "stranger"]
    assert bare[0] is False and "without the rmw_zenoh attachment" in bare[1], bare
    assert stranger[0] is False and "for another request" in stranger[1], stranger
