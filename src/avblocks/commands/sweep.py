"""``avblocks sweep``: a grid of parameter values x seeds of a scenario, run on Dask.

The command's parser and body live with the sweep (:mod:`avblocks.sweep.cli`,
next to the sweep API they call); this module is its place among the commands.
"""

from __future__ import annotations

from ..sweep.cli import add_parser, cmd_sweep

__all__ = ["add_parser", "cmd_sweep"]
