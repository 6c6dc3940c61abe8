"""Processes that try to outlive the grader.

An honest solution that, while loading, starts: a forked child that
ignores SIGTERM; a ``subprocess`` that sleeps; a daemon that double-forks
out of its session (``setsid``); and, in every ``wheels_to_cmd`` call, one
more fork. Each sleeps an hour under the marker ``avblocks-hostile-TOKEN``.
Its grades are not the point: when the grader is done, none of them may
still run (the supervisor, a child subreaper, collects even the daemon).

passes: yes
"""

import os
import signal
import subprocess
import sys

import numpy as np

import avblocks as av

MARK = "avblocks-hostile-TOKEN"
SLEEP = [sys.executable, "-c", "import time; time.sleep(3600)", MARK]


def _fork_sleeper():
    pid = os.fork()
    if pid == 0:
        try:
            signal.signal(signal.SIGTERM, signal.SIG_IGN)
            os.execv(sys.executable, SLEEP)
        finally:
            os._exit(0)


def _daemon():
    pid = os.fork()
    if pid == 0:
        try:
            os.setsid()
            if os.fork() == 0:
                os.execv(sys.executable, SLEEP)
        finally:
            os._exit(0)
    os.waitpid(pid, 0)


_fork_sleeper()
subprocess.Popen(SLEEP, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                 stderr=subprocess.DEVNULL)
_daemon()


class MyUnicycle(av.Block):
    def __init__(self, pose0):
        super().__init__()
        pose0 = np.asarray(pose0, dtype=float)
        self.n = len(pose0)
        self.declare_input("cmd", (self.n, 2), feedthrough=False)
        self.declare_continuous_state("pose", pose0)
        self.declare_output("pose", (self.n, 3))

    def output(self, t, x, u, xp):
        return {"pose": x["pose"]}

    def derivative(self, t, x, u, xp):
        pose, cmd = x["pose"], u["cmd"]
        v, w, th = cmd[:, 0], cmd[:, 1], pose[:, 2]
        return {"pose": xp.stack([v * xp.cos(th), v * xp.sin(th), w], axis=-1)}


def wheels_to_cmd(wheels, radius, track):
    _fork_sleeper()
    wl, wr = wheels[:, 0], wheels[:, 1]
    return np.stack([radius * (wr + wl) / 2, radius * (wr - wl) / track], axis=-1)
