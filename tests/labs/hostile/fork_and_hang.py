"""A grandchild that holds the channel open, and a parent that hangs.

``wheels_to_cmd`` forks a child that keeps every inherited descriptor
(the channel's too) and sleeps; the parent then sleeps as well. The old
grader waited for the pipe to close, that is for the grandchild. Now the
check times out, and the process tree dies with it.

expect: timed out after
expect: in check 'differential drive: wheels_to_cmd'
"""

import os
import sys
import time

import numpy as np

import avblocks as av

MARK = "avblocks-hostile-TOKEN"


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
        raise NotImplementedError("write MyUnicycle.derivative (eq. 1)")


def wheels_to_cmd(wheels, radius, track):
    if os.fork() == 0:
        os.execv(sys.executable, [sys.executable, "-c", "import time; time.sleep(3600)", MARK])
    time.sleep(3600)
