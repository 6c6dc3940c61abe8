"""Swapping the check functions' ``__code__`` and the grader's helpers.

Imports the lab's check module and gives every check function the code of
``lambda sub: "ok"``, and makes ``compare`` and ``check_ports`` return at
once. They are the child's copies; the grader's own never change.

expect: not written yet: NotImplementedError: write MyUnicycle.derivative
expect: MyUnicycle declares no input `cmd`
"""

import numpy as np

import avblocks as av
import avblocks.labs.grading as _grading
import avblocks.labs.lab1_kinematics as _lab1

_ok = (lambda sub: "ok").__code__
for _name in dir(_lab1):
    _fn = getattr(_lab1, _name)
    if callable(_fn) and getattr(_fn, "__code__", None) is not None and \
            _fn.__code__.co_argcount == 1:
        _fn.__code__ = _ok
_grading.compare.__code__ = (lambda *a, **k: 0.0).__code__
_grading.check_ports.__code__ = (lambda *a, **k: "ok").__code__


class MyUnicycle(av.Block):
    def __init__(self, pose0):
        super().__init__()
        pose0 = np.asarray(pose0, dtype=float)
        self.n = len(pose0)
        # no cmd input at all: only a forged check_ports would accept this
        self.declare_continuous_state("pose", pose0)
        self.declare_output("pose", (self.n, 3))

    def output(self, t, x, u, xp):
        return {"pose": x["pose"]}

    def derivative(self, t, x, u, xp):
        raise NotImplementedError("write MyUnicycle.derivative (eq. 1)")


def wheels_to_cmd(wheels, radius, track):
    raise NotImplementedError("write wheels_to_cmd")
