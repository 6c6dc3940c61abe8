"""Deep recursion: a RecursionError, and a recursion that crashes the C stack.

``derivative`` recurses without end (Python's limit: a RecursionError);
``wheels_to_cmd`` first raises the limit to a million and recurses through
a C function (``map``), which overflows the C stack and kills the process
(a segmentation fault).

expect: your code raised RecursionError: maximum recursion depth exceeded
expect: the process running your code ended (signal 11 (SIGSEGV)) in check
expect: in check 'differential drive: wheels_to_cmd' of lab 1: a crash in compiled code
"""

import sys

import numpy as np

import avblocks as av


def _down(n):
    return _down(n + 1) + 1


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
        return {"pose": _down(0)}


def _through_c(n):
    return sum(map(_through_c, [n + 1]))


def wheels_to_cmd(wheels, radius, track):
    sys.setrecursionlimit(1_000_000)
    return _through_c(0)
