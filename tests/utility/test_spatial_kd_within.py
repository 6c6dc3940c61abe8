"""NumPy radius queries through the k-d tree (``kd_within``) give the cell
list's rows entry for entry, and both equal brute force."""

import numpy as np
import pytest

from avblocks.utility import spatial as sp


def _brute_sets(p, q, r, exclude_self):
    d = q[:, None, :] - p[None, :, :]
    d2 = d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1]
    ok = d2 <= r * r
    if exclude_self:
        ok &= ~np.eye(len(q), len(p), dtype=bool)
    return [set(np.nonzero(row)[0].tolist()) for row in ok]


@pytest.mark.parametrize("case", ["random", "lattice", "at_radius", "one", "queries"])
@pytest.mark.parametrize("exclude_self", [True, False])
def test_kd_within_equals_cell_list_and_brute_force(case, exclude_self):
    rng = np.random.default_rng(7)
    p = rng.uniform(0, 10, (300, 2))
    q = None
    if case == "lattice":                     # ties, cell borders, duplicates
        p = np.round(p * 2) / 2
        p[:7] = p[7]
    elif case == "at_radius":                 # points exactly 1 apart
        p = np.stack(np.meshgrid(np.arange(12.0), np.arange(12.0)), -1).reshape(-1, 2)
    elif case == "one":
        p = p[:1]
    elif case == "queries":
        q = rng.uniform(-1, 11, (80, 2))
    for reach in (1.0, 1.7):                  # a search planned for a larger reach
        a_idx, a_d, _ = sp.within(sp.CellList(reach), p, 1.0, q, np,
                                  exclude_self=exclude_self)
        b_idx, b_d = sp.kd_within(p, 1.0, q, exclude_self=exclude_self, reach=reach)
        np.testing.assert_array_equal(b_idx, a_idx)
        np.testing.assert_array_equal(b_d, a_d)
    want = _brute_sets(p, p if q is None else q, 1.0, exclude_self and q is None)
    got = [set(row[row >= 0].tolist()) for row in b_idx]
    assert got == want


def test_neighbor_search_within_uses_the_tree_in_free_space_only():
    p = np.random.default_rng(1).uniform(0, 6, (100, 2))
    s = sp.NeighborSearch(1.0)
    idx, dist = s.within(p, 0.8)
    ref, rd, _ = sp.within(sp.CellList(1.0), p, 0.8, None, np)
    np.testing.assert_array_equal(idx, ref)
    np.testing.assert_array_equal(dist, rd)
    box = sp.NeighborSearch(1.0, box=(6.0, 6.0))       # periodic: the cell list
    bi, _ = box.within(p, 0.8)
    ri, _, _ = sp.within(sp.CellList(1.0, box=(6.0, 6.0)), p, 0.8, None, np)
    np.testing.assert_array_equal(bi, ri)
