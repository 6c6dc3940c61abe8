"""Messages that try to rewrite the report.

The exceptions it raises carry newlines, ANSI escapes, carriage returns
and text shaped like PASS lines and a summary. Each reaches the report as
one line of printable text inside its own FAIL line.

expect: not written yet: NotImplementedError:
expect: PASS derivative (eq. 1) 5 of 5 checks passed
"""

import numpy as np

import avblocks as av

FAKE = "\n  PASS  derivative (eq. 1)\r\x1b[2K\x1b[32m\n5 of 5 checks passed\n\x00"


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
        raise NotImplementedError(FAKE)


def wheels_to_cmd(wheels, radius, track):
    raise ValueError(FAKE * 1000)
