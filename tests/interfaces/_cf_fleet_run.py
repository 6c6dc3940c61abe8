"""A separate avblocks process flying Crazyflies, for the signal and guard
tests: ``python _cf_fleet_run.py ROUTER NAMES T_FINAL FLIGHT_LOG RESULTS
[--pause-at T --pause S]`` flies every vehicle at 0.1 m/s along x through a
``Crazyflies`` block in real time, prints ``started`` at the first mission
step, and saves the results (also those of an interrupted run) to
RESULTS, printing ``saved``. With ``--pause-at``, the diagram's step at
time T takes S seconds more (a legitimately slow step)."""

from __future__ import annotations

import sys
import time

import numpy as np

import avblocks as av
from avblocks.core.block import Block
from avblocks.interfaces.crazyflie import Crazyflies


class _Started(Block):
    """Prints ``started`` at its first major step (after every on_start);
    sleeps ``pause`` seconds once at the step at ``pause_at``."""

    side_effects = True

    def __init__(self, pause_at=None, pause=0.0):
        super().__init__()
        self.said = False
        self.pause_at, self.pause = pause_at, pause

    def output(self, t, x, u, xp):
        return {}

    def on_major_step(self, t, x, u, y):
        if not self.said:
            print("started", flush=True)
            self.said = True
        if self.pause_at is not None and t >= self.pause_at:
            self.pause_at = None
            print(f"pausing {self.pause:g} s", flush=True)
            time.sleep(self.pause)


def main(router, names, t_final, flight_log, results, *opts):
    kw = dict(zip(opts[::2], opts[1::2]))
    names = names.split(",")
    d = av.Diagram()
    c = d.add(av.blocks.Constant(np.tile([0.1, 0.0, 0.0], (len(names), 1))), name="c")
    f = d.add(Crazyflies(names, router, takeoff_height=0.5, land_duration=1.5,
                         log=flight_log), name="fleet")
    d.connect(c.y, f.velocity)
    pause_at = kw.get("--pause-at")
    d.add(_Started(None if pause_at is None else float(pause_at),
                   float(kw.get("--pause", 0.0))), name="started")
    res = av.simulate(d, t_final=float(t_final), dt=0.05, realtime=1.0,
                      log=["fleet.position"], progress=False)
    res.save(results)
    print("saved", flush=True)


if __name__ == "__main__":
    main(*sys.argv[1:])
