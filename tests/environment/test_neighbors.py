"""Neighbours: brute-force distance matrix, hand-built field of view, graph."""

import networkx as nx
import numpy as np
import pytest

import avblocks as av
from avblocks.environment import (
    PAD_DISTANCE,
    Neighbors,
    fov_neighbors,
    knn,
    radius_neighbors,
    to_networkx,
)


def brute(pos, radius, k, heading=None, fov=None):
    n = len(pos)
    diff = pos[None, :, :] - pos[:, None, :]
    D = np.hypot(diff[..., 0], diff[..., 1])
    ok = (D <= radius) & ~np.eye(n, dtype=bool)
    if fov is not None:
        rel = np.arctan2(diff[..., 1], diff[..., 0]) - heading[:, None]
        rel = np.abs(np.angle(np.exp(1j * rel)))
        ok &= rel <= fov / 2
    idx = np.full((n, k), -1)
    dist = np.full((n, k), np.inf)
    for i in range(n):  # reference only
        js = np.nonzero(ok[i])[0]
        js = js[np.argsort(D[i, js], kind="stable")][:k]
        idx[i, :len(js)] = js
        dist[i, :len(js)] = D[i, js]
    return idx, dist


@pytest.mark.parametrize("radius,k", [(0.12, 8), (0.3, 5), (np.inf, 6), (0.05, 3)])
def test_radius_knn_match_brute_force(radius, k):
    gen = np.random.default_rng(1)
    pos = gen.uniform(0, 1, (400, 2))
    idx, dist = radius_neighbors(pos, radius, k)
    bi, bd = brute(pos, radius, k)
    np.testing.assert_array_equal(idx, bi)
    np.testing.assert_allclose(dist, bd)
    assert idx.dtype == np.int64


def test_knn_and_inclusive_radius():
    pos = np.array([[0.0, 0], [1, 0], [3, 0], [3, 4]])
    idx, dist = radius_neighbors(pos, 1.0, 3)  # exactly 1.0 apart: included
    assert idx.tolist() == [[1, -1, -1], [0, -1, -1], [-1, -1, -1], [-1, -1, -1]]
    idx, dist = knn(pos, 2)
    assert idx.tolist() == [[1, 2], [0, 2], [1, 0], [2, 1]]
    np.testing.assert_allclose(dist[3], [4.0, np.hypot(2, 4)])


def test_fov_hand_built():
    pos = np.array([[0, 0], [1, 0], [1, 0.9], [1, 1.1], [-0.5, 0], [0, 1]], float)
    pose = np.c_[pos, np.zeros(6)]
    idx, dist = fov_neighbors(pose, np.inf, 5, np.pi / 2)  # +-45 degrees
    assert idx[0].tolist() == [1, 2, -1, -1, -1]
    np.testing.assert_allclose(dist[0, :2], [1.0, np.hypot(1, 0.9)])
    pose[0, 2] = np.pi / 2  # now looking up: (0, 1) at 0 deg, (1, 1.1) at 42.3 deg
    idx, _ = fov_neighbors(pose, np.inf, 5, np.pi / 2)
    assert idx[0].tolist() == [5, 3, -1, -1, -1]
    pose[0, 2] = np.pi  # looking back: only (-0.5, 0)
    idx, _ = fov_neighbors(pose, 0.4, 5, np.pi / 2)
    assert idx[0].tolist() == [-1] * 5  # out of range 0.4
    idx, _ = fov_neighbors(pose, 0.5, 5, np.pi / 2)
    assert idx[0].tolist() == [4, -1, -1, -1, -1]


@pytest.mark.parametrize("radius,k,fov", [(np.inf, 3, 0.5), (0.2, 4, np.pi), (0.5, 10, 2.0)])
def test_fov_random_against_brute_force(radius, k, fov):
    gen = np.random.default_rng(3)
    pose = np.c_[gen.uniform(0, 1, (300, 2)), gen.uniform(-np.pi, np.pi, 300)]
    idx, dist = fov_neighbors(pose, radius, k, fov)
    bi, bd = brute(pose[:, :2], radius, k, pose[:, 2], fov)
    np.testing.assert_array_equal(idx, bi)
    np.testing.assert_allclose(dist, bd)


def test_to_networkx():
    idx = np.array([[1, -1], [2, -1], [-1, -1], [-1, -1]])
    g = to_networkx(idx, np.array([[1.0, 0], [2.0, 0], [0, 0], [0, 0]]))
    assert sorted(g.nodes) == [0, 1, 2, 3]
    assert sorted(map(sorted, g.edges)) == [[0, 1], [1, 2]]
    assert g.edges[1, 2]["distance"] == 2.0
    assert not nx.is_connected(g)
    assert to_networkx(idx, directed=True).has_edge(0, 1)
    assert not to_networkx(idx, directed=True).has_edge(1, 0)


def test_block_in_simulation():
    pose0 = np.array([[0.0, 0, 0], [1, 0, 0], [0, 2, 0]])
    d = av.Diagram()
    f = d.add(av.vehicles.Unicycle(pose0=pose0), name="f")
    c = d.add(av.blocks.Constant(np.zeros((3, 2))), name="c")
    d.connect(c.y, f.cmd)
    nb = d.add(Neighbors(3, 2, radius=1.5, fov=np.pi), name="nb")
    d.connect(f.pose, nb.pose)
    res = av.simulate(d, 0.05, dt=0.01, log=[nb.neighbors, nb.distance])
    assert res[nb.neighbors].shape == (6, 3, 2)
    # agent 0 faces +x: sees 1 (ahead); agent 1 faces +x: 0 is behind
    assert res[nb.neighbors][-1].tolist() == [[1, -1], [-1, -1], [-1, -1]]
    assert res[nb.distance][-1].tolist() == [[1.0, PAD_DISTANCE], [PAD_DISTANCE] * 2,
                                             [PAD_DISTANCE] * 2]


def test_block_errors():
    with pytest.raises(av.ParameterError):
        Neighbors(3, 2, fov=1.0, input="position")
    with pytest.raises(av.ParameterError):
        Neighbors(3, 0)
    with pytest.raises(av.ParameterError):
        Neighbors(3, 2, radius=-1)
