"""A separate avblocks process commanding robots, for the fault tests:
``python _fleet_run.py ROUTER NAMES T_FINAL [V]`` drives every robot at
``V`` m/s (default 0.2) in real time through a ``Robots`` block, prints
``started`` once connected and ``done`` at the end."""

from __future__ import annotations

import sys

import numpy as np

import avblocks as av
from avblocks.core.block import Block
from avblocks.interfaces.ros2 import Robots


class _Started(Block):
    """Prints ``started`` at its first major step (after every on_start)."""

    side_effects = True

    def __init__(self):
        super().__init__()
        self.said = False

    def output(self, t, x, u, xp):
        return {}

    def on_major_step(self, t, x, u, y):
        if not self.said:
            print("started", flush=True)
            self.said = True


def main(router, names, t_final, v=0.2):
    names = names.split(",")
    d = av.Diagram()
    c = d.add(av.blocks.Constant(np.tile([float(v), 0.0], (len(names), 1))), name="c")
    f = d.add(Robots(names, router=router), name="fleet")
    d.connect(c.y, f.cmd)
    d.add(_Started(), name="started")
    av.simulate(d, t_final=float(t_final), dt=0.05, realtime=1.0, progress=False)
    print("done", flush=True)


if __name__ == "__main__":
    main(*sys.argv[1:])
