"""A frame that claims more than the grader takes.

Writes (as its very first bytes on the channel) a well-formed frame whose
blobs add up to 10 GB. The grader refuses it from the header, before
reading or allocating anything.

expect: broke the grader's channel while loading the file
expect: over the limit of 16777216 bytes
"""

import os
import stat
import struct

import numpy as np

import avblocks as av

_head = b'{"v": null, "b": [10000000000]}'
for fd in range(3, 64):
    try:
        if stat.S_ISFIFO(os.fstat(fd).st_mode):
            os.write(fd, b"AVL1" + struct.pack(">I", len(_head)) + _head)
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
