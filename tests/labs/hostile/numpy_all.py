"""Monkeypatching NumPy: ``numpy.all = lambda *a, **k: True``.

A wrong solution (the turn rate's sign flipped) that also makes every
NumPy comparison say "equal". The grader compares in its own process,
with its own NumPy: the wrong sign is found as before.

expect: port `pose (its rate, derivative)`
expect: expected [
"""

import numpy
import numpy as np

import avblocks as av

numpy.all = lambda *a, **k: True
numpy.allclose = lambda *a, **k: True
numpy.array_equal = lambda *a, **k: True
numpy.isfinite = lambda x, *a, **k: numpy.ones(numpy.shape(x), bool)
numpy.testing.assert_allclose = lambda *a, **k: None


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
        return {"pose": xp.stack([v * xp.cos(th), v * xp.sin(th), -w], axis=-1)}


def wheels_to_cmd(wheels, radius, track):
    wl, wr = wheels[:, 0], wheels[:, 1]
    return np.stack([radius * (wr + wl) / 2, radius * (wr - wl) / track], axis=-1)
