"""The same link interface over rclpy, for machines with a ROS 2 install.

Messages travel as serialized CDR (``raw=True`` subscriptions, publishing
bytes), so the block's encoding and decoding are the same as over Zenoh.
Only importable where ``rclpy`` is (not tested in this repository's CI,
which has no ROS 2).
"""

from __future__ import annotations

import threading
import time

from ...core.errors import ParameterError


def available() -> bool:
    try:
        import rclpy  # noqa: F401
    except ImportError:
        return False
    return True


class RclpyLink:
    """A node with publishers and raw subscriptions, spun in a thread."""

    def __init__(self, node="avblocks", namespace="/", **_ignored):
        if not available():
            raise ParameterError(
                "transport='rclpy' needs a ROS 2 installation (rclpy is not importable)",
                param="transport",
                hint="source /opt/ros/<distro>/setup.bash, or use transport='bridge' "
                     "or 'rmw_zenoh'")
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        self.convention = "rclpy"
        if not rclpy.ok():
            rclpy.init()
        self._node = rclpy.create_node(node, namespace=namespace)
        self._exec = SingleThreadedExecutor()
        self._exec.add_node(self._node)
        self._thread = threading.Thread(target=self._exec.spin, daemon=True)
        self._thread.start()

    @staticmethod
    def _type(typename):
        import importlib
        pkg, kind, name = typename.split("/")
        return getattr(importlib.import_module(f"{pkg}.{kind}"), name)

    def publisher(self, topic, typename):
        pub = self._node.create_publisher(self._type(typename), "/" + topic.strip("/"), 10)

        class _P:
            def put(self, payload):
                pub.publish(bytes(payload))
        return _P()

    def subscribe(self, topic, typename, callback):
        return self._node.create_subscription(
            self._type(typename), "/" + topic.strip("/"),
            lambda data: callback(bytes(data), time.monotonic()), 10, raw=True)

    def close(self):
        self._exec.shutdown()
        self._node.destroy_node()
