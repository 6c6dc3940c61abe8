"""Reading what is not its own: the class folder, the reference solutions,
an instructor's files.

While loading, lists the folder its file came from (the class folder) and
reads every other submission there; reads the reference solutions beside
the installed package's tests (an editable install, as the course page
installs it, keeps them on disk) and ``/etc/shadow``. A submission that
passes by running another student's file, read at grading time, would
leave nothing for a plagiarism check to find. Under Landlock the student's
process reads only its own folder, the Python installation, avblocks and
system folders, so ``wheels_to_cmd`` finds nothing to report.

expect: your code raised LookupError: read nothing
"""

import os
from pathlib import Path

import numpy as np

import avblocks as av

READ = []


def _read(path):
    try:
        with open(path, "rb") as f:
            if f.read(1):
                READ.append(Path(path).name)
    except OSError:
        pass


try:
    _mine = Path(__file__)
    for _name in os.listdir(_mine.parent):
        if _name != _mine.name:
            _read(_mine.parent / _name)
except OSError:
    pass
_read(Path(av.__file__).resolve().parents[2] / "tests" / "labs" / "solutions"
      / "lab1_kinematics.py")
_read("/etc/shadow")


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
    raise LookupError(f"read {', '.join(READ)}" if READ else "read nothing")
