"""A stand-in for Crazyswarm2's ``crazyflie_server`` written with
zenoh-ros2-sdk (an rmw_zenoh implementation in plain Python that nobody
here wrote), run as a subprocess by test_crazyflie_interop.py. Its type
hashes are computed by the SDK from the interface texts below (those of
crazyflie_interfaces 1.0.5), so nothing of avblocks decides what it
accepts.

For one vehicle ``cf1`` it serves ``/cf1/takeoff``, ``/cf1/land`` and
``/cf1/notify_setpoints_stop``, subscribes ``/cf1/cmd_full_state`` and
``/cf1/cmd_velocity_world``, writes everything it receives (decoded by the
SDK) to a JSON-lines file, and publishes ``/cf1/pose`` at 50 Hz: at START
on the floor, climbing linearly to a takeoff's height over its duration,
going down likewise on a land.

Usage: python _cf_sdk_peer.py HOST PORT MSG_DIR OUT_FILE [SECONDS]
"""

import json
import sys
import threading
import time
from pathlib import Path

DEFS = {
    "builtin_interfaces/msg/Time": "int32 sec\nuint32 nanosec\n",
    "builtin_interfaces/msg/Duration": "int32 sec\nuint32 nanosec\n",
    "std_msgs/msg/Header": "builtin_interfaces/Time stamp\nstring frame_id\n",
    "geometry_msgs/msg/Vector3": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/msg/Point": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/msg/Quaternion": "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    "geometry_msgs/msg/Pose": "Point position\nQuaternion orientation\n",
    "geometry_msgs/msg/Twist": "Vector3 linear\nVector3 angular\n",
    "geometry_msgs/msg/PoseStamped": "std_msgs/Header header\nPose pose\n",
    "crazyflie_interfaces/msg/FullState": ("std_msgs/Header header\ngeometry_msgs/Pose pose\n"
                                           "geometry_msgs/Twist twist\n"
                                           "geometry_msgs/Vector3 acc\n"),
    "crazyflie_interfaces/msg/VelocityWorld": ("std_msgs/Header header\n"
                                               "geometry_msgs/Vector3 vel\n"
                                               "float32 yaw_rate\n"),
}
SRVS = {
    "takeoff": ("crazyflie_interfaces/srv/Takeoff",
                "uint8 group_mask\nfloat32 height\nbuiltin_interfaces/Duration duration\n"),
    "land": ("crazyflie_interfaces/srv/Land",
             "uint8 group_mask\nfloat32 height\nbuiltin_interfaces/Duration duration\n"),
    "notify_setpoints_stop": ("crazyflie_interfaces/srv/NotifySetpointsStop",
                              "uint8 group_mask\nuint32 remain_valid_millisecs\n"),
}
START = (0.25, -0.5, 0.0)


def main():
    host, port, msg_dir, out = sys.argv[1:5]
    seconds = float(sys.argv[5]) if len(sys.argv) > 5 else 60.0
    for name, text in DEFS.items():
        f = Path(msg_dir) / f"{name}.msg"
        f.parent.mkdir(parents=True, exist_ok=True)
        f.write_text(text)
    import zenoh_ros2_sdk as sdk
    from zenoh_ros2_sdk.utils import compute_service_type_hash, get_type_hash
    sdk.get_registry(msg_dir)
    log = open(out, "a", buffering=1)
    lock = threading.Lock()
    z = {"from": 0.0, "to": 0.0, "t0": 0.0, "dur": 1.0}

    def write(rec):
        with lock:
            log.write(json.dumps({"wall": time.time(), **rec}) + "\n")

    def deps(text):
        """Every definition ``text`` needs, nested ones included."""
        out, todo = {}, [text]
        while todo:
            t = todo.pop()
            for k, v in DEFS.items():
                if k not in out and k.rsplit("/", 1)[1] in t:
                    out[k] = v
                    todo.append(v)
        return out

    def height_now():
        s = min(max((time.time() - z["t0"]) / z["dur"], 0.0), 1.0)
        return z["from"] + s * (z["to"] - z["from"])

    servers = []
    servers_by_name = {}
    for short, (srv, req) in SRVS.items():
        h = compute_service_type_hash(srv, req, "# empty", dependencies=deps(req))

        def cb(r, short=short):
            d = {k: getattr(r, k) for k in ("group_mask", "height", "remain_valid_millisecs")
                 if hasattr(r, k)}
            if hasattr(r, "duration"):
                d["duration"] = r.duration.sec + 1e-9 * r.duration.nanosec
            write({"ev": short, **{k: float(v) for k, v in d.items()}})
            if short in ("takeoff", "land"):
                z.update({"from": height_now(), "to": float(r.height), "t0": time.time(),
                          "dur": max(d["duration"], 1e-3)})
            return servers_by_name[short].response_msg_class()
        s = sdk.ROS2ServiceServer(f"/cf1/{short}", srv, cb, request_definition=req,
                                  response_definition="", router_ip=host,
                                  router_port=int(port), type_hash=h, domain_id=0,
                                  node_name="crazyflie_server")
        servers.append(s)
        servers_by_name[short] = s

    def on_full(m):
        p, v, a = m.pose.position, m.twist.linear, m.acc
        write({"ev": "full_state", "pos": [p.x, p.y, p.z], "vel": [v.x, v.y, v.z],
               "acc": [a.x, a.y, a.z], "quat": [m.pose.orientation.w, m.pose.orientation.x,
                                                m.pose.orientation.y, m.pose.orientation.z],
               "stamp": m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec})

    def on_vel(m):
        write({"ev": "velocity", "vel": [m.vel.x, m.vel.y, m.vel.z],
               "yaw_rate": float(m.yaw_rate),
               "stamp": m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec})

    full = "crazyflie_interfaces/msg/FullState"
    velw = "crazyflie_interfaces/msg/VelocityWorld"
    subs = [sdk.ROS2Subscriber("/cf1/cmd_full_state", full, on_full, router_ip=host,
                               router_port=int(port), domain_id=0,
                               type_hash=get_type_hash(full, msg_definition=DEFS[full],
                                                       dependencies=deps(DEFS[full])),
                               node_name="crazyflie_server"),
            sdk.ROS2Subscriber("/cf1/cmd_velocity_world", velw, on_vel, router_ip=host,
                               router_port=int(port), domain_id=0,
                               type_hash=get_type_hash(velw, msg_definition=DEFS[velw],
                                                       dependencies=deps(DEFS[velw])),
                               node_name="crazyflie_server")]
    ps = "geometry_msgs/msg/PoseStamped"
    pub = sdk.ROS2Publisher("/cf1/pose", ps, router_ip=host, router_port=int(port),
                            domain_id=0, node_name="crazyflie_server",
                            type_hash=get_type_hash(ps, msg_definition=DEFS[ps],
                                                    dependencies=deps(DEFS[ps])))
    from zenoh_ros2_sdk.session import ZenohSession
    T = ZenohSession.get_instance(host, int(port)).store.types
    print("ready", flush=True)
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        now = time.time()
        header = T["std_msgs/msg/Header"](
            stamp=T["builtin_interfaces/msg/Time"](sec=int(now), nanosec=int(now % 1 * 1e9)),
            frame_id="world")
        pose = T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=START[0], y=START[1], z=height_now()),
            orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0))
        pub.publish(header=header, pose=pose)
        time.sleep(0.02)
    for s in servers + subs + [pub]:
        s.close()


if __name__ == "__main__":
    main()
