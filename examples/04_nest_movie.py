"""A movie of information spreading through the nest (AVLib case study IV.B).

    python examples/04_nest_movie.py [AGENTS]

Runs the built-in ``nest`` scenario (``avblocks.scenarios.nest``) with
AGENTS random-walking agents (default 500), five informed scouts at the
entrance, and writes nest.mp4 with the agents coloured by the
``gossip.informed`` flag (red: informed), plus the time everyone knew.
"""

import os
import sys

import numpy as np

import avblocks as av
from avblocks.scenarios import nest

agents = int(sys.argv[1]) if len(sys.argv) > 1 else 500
small = bool(os.environ.get("AVBLOCKS_EXAMPLE_SMALL"))

d, sim = nest.make_diagram(agents=agents, t_final=4.0 if small else 100.0)
res = av.simulate(d, progress=False, **sim)

count = res["gossip.informed"].sum(axis=1)
full = np.flatnonzero(count == agents)
when = f"everyone informed at t = {res.t[full[0]]:.1f} s" if len(full) else \
    f"{count[-1]} of {agents} informed at t = {res.t[-1]:g} s"
print(f"{agents} agents: {when}")

options = dict(nest.MOVIE)                  # {"color": "gossip.informed", "every": 2}
if small:
    options["every"] = 10
path = av.viz.save_movie(res, "nest.mp4", **options)
print(f"wrote {path}")
