import numpy as np
import pytest
import shapely
from scipy.spatial.distance import pdist

import avblocks as av
from avblocks.utility import random_poses, random_positions


def min_dist(p):
    return pdist(p[:, :2]).min()     # brute force over all pairs


def test_box_area_and_separation():
    p = random_poses(200, area=(20.0, 10.0), min_separation=0.8, seed=3)
    assert p.shape == (200, 3)
    assert min_dist(p) >= 0.8
    assert p[:, 0].min() >= 0 and p[:, 0].max() <= 20
    assert p[:, 1].min() >= 0 and p[:, 1].max() <= 10
    assert np.all(p[:, 2] > -np.pi) and np.all(p[:, 2] <= np.pi)


def test_bounds_form_and_uniformity():
    p = random_positions(4000, area=(-5.0, 5.0, 10.0, 12.0), seed=0)
    assert p.shape == (4000, 2)
    assert p[:, 0].min() >= -5 and p[:, 0].max() <= 5
    assert p[:, 1].min() >= 10 and p[:, 1].max() <= 12
    # roughly uniform: each half of the box holds about half of the points
    frac = np.mean(p[:, 0] < 0)
    assert 0.46 < frac < 0.54
    th = random_poses(4000, seed=1)[:, 2]
    assert 0.46 < np.mean(th > 0) < 0.54


@pytest.mark.parametrize("as_shapely", [False, True])
def test_polygon_area(as_shapely):
    verts = np.array([[0, 0], [10, 0], [10, 10], [5, 2], [0, 10]], dtype=float)  # concave
    area = shapely.Polygon(verts) if as_shapely else verts
    p = random_poses(60, area=area, min_separation=0.5, seed=7)
    poly = shapely.Polygon(verts)
    assert np.all(shapely.contains_xy(poly, p[:, 0], p[:, 1]))
    assert min_dist(p) >= 0.5


def test_seeded_and_generator():
    a = random_poses(30, area=(5, 5), min_separation=0.3, seed=11)
    b = random_poses(30, area=(5, 5), min_separation=0.3, seed=11)
    np.testing.assert_array_equal(a, b)
    c = random_poses(30, area=(5, 5), min_separation=0.3, seed=12)
    assert not np.array_equal(a, c)
    g = np.random.default_rng(5)
    assert random_positions(3, seed=g).shape == (3, 2)


def test_dense_but_feasible_request():
    # ~35 % of the area covered by the discs: random addition still succeeds
    n, d = 400, 1.0
    w = np.sqrt(n * np.pi * d**2 / 4 / 0.35)
    p = random_positions(n, area=(w, w), min_separation=d, seed=2)
    assert min_dist(p) >= d


def test_impossible_separation_raises_clearly():
    with pytest.raises(av.ParameterError, match="cannot fit"):
        random_poses(100, area=(1.0, 1.0), min_separation=0.5)
    # feasible in theory, beyond what random addition reaches: gives up in words
    with pytest.raises(av.ParameterError, match="could place only"):
        random_positions(100, area=(10.0, 10.0), min_separation=1.0, seed=0,
                         max_candidates=20000)


def test_parameter_errors():
    for bad in [dict(n=-1), dict(n=2.5), dict(n=3, min_separation=-1.0),
                dict(n=3, area=(1.0,)), dict(n=3, area=(1.0, 0.0, 0.0, 1.0)),
                dict(n=3, area=[[0, 0], [1, 1], [0, 1], [1, 0]])]:
        with pytest.raises(av.ParameterError):
            random_positions(**bad)
    with pytest.raises(TypeError):
        random_positions(3, spacing=1.0)
    assert random_poses(0).shape == (0, 3)
