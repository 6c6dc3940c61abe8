"""A motion-capture system stand-in written with zenoh-ros2-sdk (an
rmw_zenoh implementation nobody here wrote), run as a subprocess by
test_crazyflie_wire.py: it publishes ``/poses``
(``motion_capture_tracking_interfaces/msg/NamedPoseArray``, the SDK's own
type hash and CDR encoder) at 50 Hz, and writes every array it published
to a JSON-lines file.

Entries: ``cf1`` moving along x at 0.2 m/s from (0.5, -0.25, 0.0), level;
``cf2`` standing at (1.0, 2.0, 0.05) with yaw 0.5 rad; ``wand``, a rigid
body that is no vehicle.

Usage: python _cf_mocap_peer.py HOST PORT MSG_DIR OUT_FILE [SECONDS]
"""

import json
import math
import sys
import time
from pathlib import Path

DEFS = {
    "builtin_interfaces/msg/Time": "int32 sec\nuint32 nanosec\n",
    "std_msgs/msg/Header": "builtin_interfaces/Time stamp\nstring frame_id\n",
    "geometry_msgs/msg/Point": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/msg/Quaternion": "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    "geometry_msgs/msg/Pose": "Point position\nQuaternion orientation\n",
    # motion_capture_tracking_interfaces, as in IMRCLab/motion_capture_tracking
    "motion_capture_tracking_interfaces/msg/NamedPose": "string name\n"
                                                        "geometry_msgs/Pose pose\n",
    "motion_capture_tracking_interfaces/msg/NamedPoseArray": "std_msgs/Header header\n"
                                                             "NamedPose[] poses\n",
}
NPA = "motion_capture_tracking_interfaces/msg/NamedPoseArray"


def main():
    host, port, msg_dir, out = sys.argv[1:5]
    seconds = float(sys.argv[5]) if len(sys.argv) > 5 else 30.0
    for name, text in DEFS.items():
        f = Path(msg_dir) / f"{name}.msg"
        f.parent.mkdir(parents=True, exist_ok=True)
        f.write_text(text)
    import zenoh_ros2_sdk as sdk
    from zenoh_ros2_sdk.utils import get_type_hash
    sdk.get_registry(msg_dir)
    deps = {k: v for k, v in DEFS.items() if k != NPA}
    pub = sdk.ROS2Publisher("/poses", NPA, router_ip=host, router_port=int(port),
                            domain_id=0, node_name="motion_capture_tracking",
                            type_hash=get_type_hash(NPA, msg_definition=DEFS[NPA],
                                                    dependencies=deps))
    from zenoh_ros2_sdk.session import ZenohSession
    T = ZenohSession.get_instance(host, int(port)).store.types
    log = open(out, "a", buffering=1)
    print("ready", flush=True)
    t0 = time.time()
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        now = time.time()
        bodies = [("cf1", (0.5 + 0.2 * (now - t0), -0.25, 0.0), 0.0),
                  ("cf2", (1.0, 2.0, 0.05), 0.5),
                  ("wand", (9.0, 9.0, 9.0), 0.0)]
        poses = [T["motion_capture_tracking_interfaces/msg/NamedPose"](
            name=nm, pose=T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](x=p[0], y=p[1], z=p[2]),
                orientation=T["geometry_msgs/msg/Quaternion"](
                    x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))))
            for nm, p, yaw in bodies]
        header = T["std_msgs/msg/Header"](
            stamp=T["builtin_interfaces/msg/Time"](sec=int(now), nanosec=int(now % 1 * 1e9)),
            frame_id="world")
        pub.publish(header=header, poses=poses)
        log.write(json.dumps({"stamp": int(now) + int(now % 1 * 1e9) * 1e-9,
                              "bodies": bodies}) + "\n")
        time.sleep(0.02)
    pub.close()


if __name__ == "__main__":
    main()
