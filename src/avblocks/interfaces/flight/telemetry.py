"""What the vehicles report, as one thread-safe buffer.

Protocol threads write into a :class:`TelemetryBuffer` (each write takes
the lock once); the block reads consistent copies with :meth:`snapshot`
once per major step. Everything is in the library's world frame (ENU:
x east, y north, z up; attitude body FLU -> world ENU), converted by the
protocol layer before it is written here.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass

import numpy as np


@dataclass
class Telemetry:
    """A snapshot of N vehicles (copies; arrays with vehicles first).

    Attributes
    ----------
    position, velocity : (N, 3)
        World frame [m, m/s]; NaN before the first pose.
    attitude : (N, 4)
        Unit quaternion (w, x, y, z), body FLU -> world ENU; identity
        before the first attitude.
    pose_age, heard_age : (N,) [s]
        Time since the latest pose / since anything was heard (inf: never).
    poses : (N,) int
        Poses received so far.
    battery : (N,)
        Remaining charge in [0, 1] (NaN: not reported).
    armed, landed : (N,) bool
        As reported by the vehicle (landed True until it reports otherwise).
    status : list of str
        The latest status text of each vehicle ("" if none).
    """

    position: np.ndarray
    velocity: np.ndarray
    attitude: np.ndarray
    pose_age: np.ndarray
    heard_age: np.ndarray
    poses: np.ndarray
    battery: np.ndarray
    armed: np.ndarray
    landed: np.ndarray
    status: list


class TelemetryBuffer:
    """Latest values reported by N vehicles, written from any thread."""

    def __init__(self, n):
        self.n = n = int(n)
        self._lock = threading.Lock()
        self.reset()

    def reset(self):
        n = self.n
        with self._lock:
            self._pos = np.full((n, 3), np.nan)
            self._vel = np.zeros((n, 3))
            self._att = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
            self._t_pose = np.full(n, -np.inf)
            self._t_heard = np.full(n, -np.inf)
            self._poses = np.zeros(n, np.int64)
            self._batt = np.full(n, np.nan)
            self._armed = np.zeros(n, bool)
            self._landed = np.ones(n, bool)
            self._status = [""] * n

    def heard(self, i, now=None):
        """Vehicle ``i`` sent something (a heartbeat, any message)."""
        with self._lock:
            self._t_heard[i] = time.monotonic() if now is None else now

    def pose(self, i, position, velocity=None, now=None):
        """A world-frame position (3,) and velocity (3,) of vehicle ``i``."""
        t = time.monotonic() if now is None else now
        with self._lock:
            self._pos[i] = position
            if velocity is not None:
                self._vel[i] = velocity
            self._t_pose[i] = t
            self._t_heard[i] = t
            self._poses[i] += 1

    def attitude(self, i, q):
        """A unit quaternion (w, x, y, z), body FLU -> world ENU."""
        with self._lock:
            self._att[i] = q

    def battery(self, i, fraction):
        with self._lock:
            self._batt[i] = fraction

    def armed(self, i, armed, landed=None):
        with self._lock:
            self._armed[i] = bool(armed)
            if landed is not None:
                self._landed[i] = bool(landed)

    def status(self, i, text):
        with self._lock:
            self._status[i] = str(text)

    def snapshot(self):
        """A :class:`Telemetry` copy now."""
        now = time.monotonic()
        with self._lock:
            return Telemetry(self._pos.copy(), self._vel.copy(), self._att.copy(),
                             now - self._t_pose, now - self._t_heard, self._poses.copy(),
                             self._batt.copy(), self._armed.copy(), self._landed.copy(),
                             list(self._status))
