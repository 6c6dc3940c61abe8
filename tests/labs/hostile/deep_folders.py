"""Folders the grader must clean up.

An honest solution that, while loading, nests 1200 folders in its own
temporary folder (allowed: it is the only place it may write), and a
folder beside a file that nobody may list or enter (``mkdir(name, 0)``,
no chmod needed). Removing the folder recursively (``shutil.rmtree``) ended the whole
run in a RecursionError after this submission; the grader removes it
level by level whatever its depth and modes.

passes: yes
"""

import os

import numpy as np

import avblocks as av

_home = os.getcwd()
try:
    os.mkdir("kept")
    with open(os.path.join("kept", "inside.txt"), "w") as _f:
        _f.write("x")
    os.mkdir(os.path.join("kept", "shut"), 0)
    for _ in range(1200):
        os.mkdir("d")
        os.chdir("d")
finally:
    os.chdir(_home)


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
        return {"pose": xp.stack([v * xp.cos(th), v * xp.sin(th), w], axis=-1)}


def wheels_to_cmd(wheels, radius, track):
    wl, wr = wheels[:, 0], wheels[:, 1]
    return np.stack([radius * (wr + wl) / 2, radius * (wr - wl) / track], axis=-1)
