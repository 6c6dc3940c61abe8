"""Results too large or too deep for a message.

``wheels_to_cmd`` returns an 800 MB array (a message holds 16 MiB);
``derivative`` returns a list nested 10,000 levels deep. The student's
process refuses to send either and says why.

expect: your code returned too much: arrays of 800000000 bytes
expect: over the limit of 16777216 bytes per message
expect: your code returned too much: nested deeper than 32 levels
"""

import numpy as np

import avblocks as av


def _deep(n):
    out = []
    for _ in range(n):
        out = [out]
    return out


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
        return {"pose": _deep(10_000)}


def wheels_to_cmd(wheels, radius, track):
    return np.zeros(10 ** 8)
