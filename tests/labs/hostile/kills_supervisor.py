"""Killing its supervisor, then leaving a daemon behind.

An honest solution that, while loading, sends SIGKILL to its parent (the
supervisor, the subreaper that collects every process it starts) and then
double-forks a daemon out of its session that sleeps an hour under the
marker ``avblocks-hostile-TOKEN`` (the fork in between is waited for, so
no zombie points at the daemon's group). Where signals are not scoped by
Landlock (before Linux 6.12) the supervisor died and the daemon outlived
the grader. The signal is refused (seccomp, or Landlock's scoping), so
the supervisor collects the daemon; the grades are the solution's.

passes: yes
"""

import os
import signal
import sys

import numpy as np

import avblocks as av

MARK = "avblocks-hostile-TOKEN"
try:
    os.kill(os.getppid(), signal.SIGKILL)
except OSError:
    pass
_pid = os.fork()
if _pid == 0:
    try:
        os.setsid()
        if os.fork() == 0:
            os.setsid()
            os.execv(sys.executable, [sys.executable, "-c", "import time; time.sleep(3600)",
                                      MARK])
    finally:
        os._exit(0)
os.waitpid(_pid, 0)


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
    wl, wr = wheels[:, 0], wheels[:, 1]
    return np.stack([radius * (wr + wl) / 2, radius * (wr - wl) / track], axis=-1)
