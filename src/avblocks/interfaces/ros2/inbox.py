"""The receive side of :class:`~avblocks.interfaces.ros2.robots.Robots`:
pose payloads arrive on Zenoh's thread, are checked (size, decoding,
finite and non-degenerate values) and either land in the receive buffer or
are counted and dropped (the robot then counts as silent), and the block
reads consistent snapshots of the buffer at each major step."""

from __future__ import annotations

import time
import warnings

import numpy as np

from . import _msgs
from .errors import RobotWarning


class PoseInbox:
    """Receive buffer of the robots' poses (a part of ``Robots``: the block
    sets ``_lock``, ``_latest``, ``_recv``, ``_count``, ``_bad``,
    ``_bad_why``, ``_bad_warned`` and its configuration)."""

    def _reject(self, i, why):
        with self._lock:
            self._bad[i] += 1
            if self._bad_why[i] is None:
                self._bad_why[i] = why

    def _on_pose(self, i, data, now):
        # Zenoh's thread: anything wrong with the payload is counted and
        # dropped here; it never reaches the buffer (the robot stays silent).
        if len(data) > self.max_payload:
            return self._reject(i, f"payload of {len(data)} bytes, more than "
                                   f"max_payload={self.max_payload}")
        try:
            if self.pose_source == "odom":
                v = _msgs.decode_odometry(data, self.distro)
            else:
                v = _msgs.decode_pose_stamped(data, self.distro)
            v = np.array(v, float)
            why = _msgs.pose_problem(v, self.pose_source == "odom")
        except Exception as e:  # noqa: BLE001 - any decoding failure is bad input
            ptype = _msgs.ODOMETRY if self.pose_source == "odom" else _msgs.POSE_STAMPED
            why = f"not a {ptype} ({type(e).__name__}: {str(e)[:120]})"
        if why is not None:
            return self._reject(i, why)
        if self.pose_source == "mocap":
            tx, ty, tz, tyaw = self.tf
            c, s = np.cos(tyaw), np.sin(tyaw)
            x, y = v[0], v[1]
            v[0], v[1], v[2] = tx + c * x - s * y, ty + s * x + c * y, tz + v[2]
            v[3] = np.arctan2(np.sin(v[3] + tyaw), np.cos(v[3] + tyaw))
        with self._lock:
            if self.pose_source == "mocap":
                prev, dt = self._latest[i], v[7] - self._latest[i, 7]
                v[4:7] = (v[0:3] - prev[0:3]) / dt if np.isfinite(dt) and dt > 0 else 0.0
            self._latest[i] = v
            self._recv[i] = now
            self._count[i] += 1

    @property
    def malformed(self):
        """``{pose topic: payloads dropped}`` in this run (robots with any)."""
        with self._lock:
            bad = self._bad.copy()
        return {self.pose_topic.format(name=nm): int(c) for nm, c in zip(self.names, bad)
                if c}

    def _warn_malformed(self, final=False):
        with self._lock:
            bad, why = self._bad.copy(), list(self._bad_why)
        for i in np.nonzero(bad > 0)[0]:
            if self._bad_warned[i] and not final:
                continue
            self._bad_warned[i] = True
            topic = self.pose_topic.format(name=self.names[i])
            what = "in this run" if final else "so far"
            warnings.warn(RobotWarning(
                f"robot '{self.names[i]}': {bad[i]} malformed payload(s) on topic "
                f"'{topic}' ignored {what} (first: {why[i]}); the robot counts as "
                f"silent until valid poses arrive"), stacklevel=2)

    def snapshot(self):
        """``(latest (N, 8), age (N,) [s, scaled], counts (N,))`` now."""
        now = time.monotonic()
        with self._lock:
            latest, recv, count = self._latest.copy(), self._recv.copy(), self._count.copy()
        age = np.minimum((now - recv) * float(self.time_scale), 1e9)
        return latest, age, count

    def _state_from(self, latest, age):
        fresh = age <= float(self.timeout)
        known = np.isfinite(latest[:, 0])
        out = {"fresh": fresh & known, "age": age}
        if self.kind == "unicycle":
            out["pose"] = np.nan_to_num(latest[:, [0, 1, 3]])
        else:
            d = self.d
            out["position"] = np.nan_to_num(latest[:, :d])
            out["velocity"] = np.nan_to_num(latest[:, 4:4 + d])
        return out

