"""Reading the grader's environment.

The grader's own environment may hold an instructor's secrets (tokens,
keys); the student's process gets none of it, but could read it from
``/proc/<pid>/environ`` of the grader (the same user). While loading, it
reads the environment of every process it can and looks for the marker
variable the test sets in the grader's environment; ``wheels_to_cmd``
raises with what it found. The grader is not dumpable while it grades,
and a student's process run as root drops every capability, so nothing
is found.

expect: your code raised LookupError: found nothing
"""

import os

import numpy as np

import avblocks as av

FOUND = []
for _d in os.listdir("/proc") if os.path.isdir("/proc") else []:
    if _d.isdigit():
        try:
            with open(f"/proc/{_d}/environ", "rb") as _f:
                _env = _f.read()
        except OSError:
            continue
        if b"AVBLOCKS_HOSTILE_SECRET" in _env:
            FOUND.append(_d)


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
    raise LookupError(f"found the secret in processes {FOUND}" if FOUND else "found nothing")
