"""A ROS 2 peer written with zenoh-ros2-sdk (an rmw_zenoh implementation in
plain Python that nobody here wrote), run as a subprocess by
test_ros2_interop.py: it subscribes to ``/tb1/cmd_vel`` (Twist) and writes
what arrives to a JSON-lines file, and publishes ``/tb1/odom`` (Odometry)
with a fixed, known pose at 20 Hz.

Usage: python _sdk_peer.py HOST PORT MSG_DIR OUT_FILE TWIST_HASH ODOM_HASH
"""

import json
import math
import sys
import time
from pathlib import Path

# Standard ROS 2 interface definitions (the fields of each message), so
# that the SDK needs no network access to fetch them.
DEFS = {
    "geometry_msgs/msg/Vector3": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/msg/Twist": "Vector3 linear\nVector3 angular\n",
    "geometry_msgs/msg/Point": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/msg/Quaternion": "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    "geometry_msgs/msg/Pose": "Point position\nQuaternion orientation\n",
    "geometry_msgs/msg/PoseWithCovariance": "Pose pose\nfloat64[36] covariance\n",
    "geometry_msgs/msg/TwistWithCovariance": "Twist twist\nfloat64[36] covariance\n",
    "builtin_interfaces/msg/Time": "int32 sec\nuint32 nanosec\n",
    "std_msgs/msg/Header": "builtin_interfaces/Time stamp\nstring frame_id\n",
    "nav_msgs/msg/Odometry": ("std_msgs/Header header\nstring child_frame_id\n"
                              "geometry_msgs/PoseWithCovariance pose\n"
                              "geometry_msgs/TwistWithCovariance twist\n"),
}

#: The pose the peer publishes (x, y, z, yaw).
POSE = (1.25, -0.5, 0.0, 0.75)


def main():
    host, port, msg_dir, out, twist_hash, odom_hash = sys.argv[1:7]
    for name, text in DEFS.items():
        f = Path(msg_dir) / f"{name}.msg"
        f.parent.mkdir(parents=True, exist_ok=True)
        f.write_text(text)
    import zenoh_ros2_sdk as sdk
    sdk.get_registry(msg_dir)
    from zenoh_ros2_sdk.session import ZenohSession
    log = open(out, "a", buffering=1)

    def on_twist(m):
        log.write(json.dumps({"wall": time.time(), "v": m.linear.x, "vy": m.linear.y,
                              "w": m.angular.z}) + "\n")

    sub = sdk.ROS2Subscriber("/tb1/cmd_vel", "geometry_msgs/msg/Twist", on_twist,
                             router_ip=host, router_port=int(port), type_hash=twist_hash,
                             node_name="sdk_base", domain_id=0)
    pub = sdk.ROS2Publisher("/tb1/odom", "nav_msgs/msg/Odometry", router_ip=host,
                            router_port=int(port), type_hash=odom_hash,
                            node_name="sdk_base", domain_id=0)
    T = ZenohSession.get_instance(host, int(port)).store.types
    import numpy as np
    x, y, z, yaw = POSE
    pose = T["geometry_msgs/msg/PoseWithCovariance"](
        pose=T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=x, y=y, z=z),
            orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2),
                                                          w=math.cos(yaw / 2))),
        covariance=np.zeros(36))
    vec = T["geometry_msgs/msg/Vector3"]
    twist = T["geometry_msgs/msg/TwistWithCovariance"](
        twist=T["geometry_msgs/msg/Twist"](linear=vec(x=0.0, y=0.0, z=0.0),
                                           angular=vec(x=0.0, y=0.0, z=0.0)),
        covariance=np.zeros(36))
    print("ready", flush=True)
    end = time.monotonic() + float(sys.argv[7]) if len(sys.argv) > 7 else None
    while end is None or time.monotonic() < end:
        now = time.time()
        header = T["std_msgs/msg/Header"](
            stamp=T["builtin_interfaces/msg/Time"](sec=int(now), nanosec=int(now % 1 * 1e9)),
            frame_id="odom")
        pub.publish(header=header, child_frame_id="tb1/base_link", pose=pose, twist=twist)
        time.sleep(0.05)
    sub.close()
    pub.close()


if __name__ == "__main__":
    main()
