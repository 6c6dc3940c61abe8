"""Writing into the grader's own files.

While loading, creates a file inside the installed ``avblocks.labs``
package (where a later grader run would find it) and sets the time of the
check module. Landlock refuses both. (Where there is no Landlock the
grader notices its files changed and stops with status 2: grade in a
read-only installation.)

expect: not written yet: NotImplementedError: write MyUnicycle.derivative
"""

import os
from pathlib import Path

import numpy as np

import avblocks as av

_labs = Path(av.__file__).resolve().parent / "labs"
try:
    (_labs / "_hostile_sentinel_TOKEN.txt").write_text("planted\n")
except OSError:
    pass
try:
    os.utime(_labs / "lab1_kinematics.py")
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
