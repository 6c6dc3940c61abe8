"""Reaching the grader's objects: ``sys._getframe()`` and ``gc.get_objects()``.

Walks every frame up the stack and every object the garbage collector
knows, and empties anything that looks like a lab's checks, marks anything
that looks like a result passed, and replaces the check modules' checks.
In the new grader those objects are in another process: what this finds
is the child's own copy of the library, which grades nothing.

expect: not written yet: NotImplementedError: write MyUnicycle.derivative
expect: not written yet: NotImplementedError: write wheels_to_cmd
"""

import gc
import sys

import numpy as np

import avblocks as av
import avblocks.labs.registry as _registry

_f = sys._getframe()
while _f is not None:
    for _v in list(_f.f_locals.values()):
        if hasattr(_v, "checks") and isinstance(getattr(_v, "checks", None), list):
            _v.checks.clear()
    _f = _f.f_back
for _o in gc.get_objects():
    try:
        if hasattr(_o, "passed") and not isinstance(_o, type):
            _o.passed = True
        if type(_o).__name__ == "Lab":
            _o.checks.clear()
    except Exception:
        pass
for _lab in _registry.LABS:
    _lab.checks[:] = [(name, lambda sub: "passed (forged)") for name, _ in _lab.checks]


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
