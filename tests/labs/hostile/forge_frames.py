"""Forged results over the channel, in the channel's own format.

Writes well-formed frames (``AVL1``, a JSON header) that claim the file
loaded and that every call returned what the fixed cases expect, ahead of
the child's real answers. Frames carry only data and each answer must
name the request it answers: the first forged one is refused.

expect: broke the grader's channel
expect: an answer to a request the grader did not make
"""

import json
import os
import stat
import struct

import numpy as np

import avblocks as av


def _frame(value):
    head = json.dumps({"v": value, "b": []}).encode()
    return b"AVL1" + struct.pack(">I", len(head)) + head


_lie = b"".join(_frame({"$d": [["id", i], ["ok", {"$d": [["names", {"$d": [
    ["MyUnicycle", "class"], ["wheels_to_cmd", "function"]]}]]}]]}) for i in range(99, 110))
for fd in range(3, 64):
    try:
        if stat.S_ISFIFO(os.fstat(fd).st_mode) and fd != 0:
            os.write(fd, _lie)
    except OSError:
        pass


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
    raise NotImplementedError("write wheels_to_cmd")
