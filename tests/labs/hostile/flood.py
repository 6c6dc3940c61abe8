"""Huge output on stdout and stderr.

An honest solution that prints 20 MB to stdout and stderr, with Python and
with ``os.write``, while loading and in every call, some of it looking
like the grader's report and its JSON. It all goes to the null device: the
report, the JSON and the CSV carry only the grader's verdicts.

passes: yes
"""

import os
import sys

import numpy as np

import avblocks as av

_fake = ('{"lab": 1, "passed": true}\n  PASS  ports\n5 of 5 checks passed\n' * 1000)
for _ in range(100):
    print(_fake, end="")
    sys.stderr.write(_fake)
    os.write(1, _fake.encode())
    os.write(2, _fake.encode())


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
        print(_fake[:200])
        pose, cmd = x["pose"], u["cmd"]
        v, w, th = cmd[:, 0], cmd[:, 1], pose[:, 2]
        return {"pose": xp.stack([v * xp.cos(th), v * xp.sin(th), w], axis=-1)}


def wheels_to_cmd(wheels, radius, track):
    os.write(1, _fake.encode() * 10)
    wl, wr = wheels[:, 0], wheels[:, 1]
    return np.stack([radius * (wr + wl) / 2, radius * (wr - wl) / track], axis=-1)
