"""Garbage bytes, an oversized header and a claim of ten gigabytes.

Writes random bytes into every pipe it can, then a frame header that
announces a 2 GiB header, then one whose blobs add up to 10 GB. The
grader reads the first bytes, sees they are not a frame and stops
reading: nothing is allocated for the claims.

expect: broke the grader's channel while loading the file
"""

import os
import random
import stat
import struct

import numpy as np

import avblocks as av

_rng = random.Random(46)
_junk = bytes(_rng.randrange(256) for _ in range(65536))
_big_header = b"AVL1" + struct.pack(">I", 2 ** 31)
_big_blobs = b'{"v": null, "b": [10000000000]}'
_big_blobs = b"AVL1" + struct.pack(">I", len(_big_blobs)) + _big_blobs
for fd in range(3, 64):
    try:
        if stat.S_ISFIFO(os.fstat(fd).st_mode):
            os.write(fd, _junk + _big_header + _big_blobs)
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
