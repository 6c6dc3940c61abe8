"""Writing into the class folder: another student's file, a new file.

While loading, overwrites ``alice.py`` (another submission of the folder)
with a file that fails, writes a new ``zzz_planted.py`` beside it, and a
file in ``/tmp``. Landlock refuses each; where there is no Landlock the
grader graded every file from the copy it read before any code ran, and
fails this submission for changing the folder.

expect: not written yet: NotImplementedError: write MyUnicycle.derivative
"""

from pathlib import Path

import numpy as np

import avblocks as av

_here = Path(__file__).resolve().parent
for _path, _text in ((_here / "alice.py", "raise SystemExit('overwritten by a classmate')\n"),
                     (_here / "zzz_planted.py", "x = 1\n"),
                     (Path("/tmp") / "avblocks-hostile-TOKEN.txt", "written\n")):
    try:
        _path.write_text(_text)
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
