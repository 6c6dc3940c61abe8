"""``leader_tree(..., "nearest")``: each agent follows the nearest agent
with a lower index (ties to the lower index), checked against a plain
one-agent-at-a-time loop; memory stays bounded for large formations (all
N^2 distances at once took about 22 GB for 30,000 agents)."""

import math
import tracemalloc

import numpy as np
import pytest

from avblocks.controllers.formations import SHAPES, formation_offsets, leader_tree


def _by_hand(off):
    """The definition, agent by agent, in pure Python."""
    leader = [-1]
    for i in range(1, len(off)):
        best, arg = math.inf, -1
        for j in range(i):
            dx, dy = off[i][0] - off[j][0], off[i][1] - off[j][1]
            d = math.sqrt(dx * dx + dy * dy)   # a norm's rounding: ties stay ties
            if d < best:                  # strict: a tie keeps the lower index
                best, arg = d, j
        leader.append(arg)
    return leader


@pytest.mark.parametrize("shape", SHAPES)
def test_nearest_tree_of_every_shape_equals_the_definition(shape):
    for n in (1, 2, 5, 40, 301):
        off = formation_offsets(shape, n, 1.7)
        assert leader_tree(off).tolist() == _by_hand(off.tolist()), (shape, n)


def test_nearest_tree_of_random_offsets_equals_the_definition():
    off = np.random.default_rng(3).normal(size=(700, 2)) * 5.0
    assert leader_tree(off).tolist() == _by_hand(off.tolist())


def test_nearest_tree_memory_does_not_grow_with_the_square():
    off = formation_offsets("grid", 6000, 1.0)
    tracemalloc.start()
    try:
        leader = leader_tree(off)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 30e6, peak        # all pairs at once: 6000^2 x 24 B = 864 MB
    # the grid, row by row: the first row follows its left neighbour; in
    # the rows behind, the cell in front is as near and has the lower index
    cols = math.ceil(math.sqrt(6000))
    k = np.arange(1, 6000)
    assert leader[1:].tolist() == np.where(k < cols, k - 1, k - cols).tolist()
