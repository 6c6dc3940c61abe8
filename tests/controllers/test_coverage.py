"""Coverage (Lloyd): cost and centroids against grid integration; H decreases."""

import numpy as np
import pytest
import shapely

import avblocks as av
from avblocks.controllers.coverage import Coverage, cell_moments, coverage_cost

POLY = np.array([[0, 0], [4, 0], [5, 3], [2, 5], [-1, 3]], float)


def _grid_truth(p, h=0.005):
    g = np.arange(-1, 5, h) + h / 2
    x, y = np.meshgrid(g, g)
    q = np.column_stack([x.ravel(), y.ravel()])
    q = q[shapely.contains_xy(shapely.Polygon(POLY), q[:, 0], q[:, 1])]
    d2 = ((q[:, None, :] - p[None]) ** 2).sum(-1)
    owner = d2.argmin(1)
    area = np.bincount(owner, minlength=len(p)) * h * h
    cen = np.stack([np.bincount(owner, q[:, k], len(p)) for k in range(2)], -1) * h * h
    return area, cen / area[:, None], d2.min(1).sum() * h * h


def test_cost_and_centroids_match_grid_integration():
    p = np.random.default_rng(0).uniform(0.5, 3, (7, 2))
    area, cen, cost = cell_moments(p, POLY)
    ga, gc, gh = _grid_truth(p)
    np.testing.assert_allclose(area.sum(), 21.0, rtol=1e-12)   # shoelace of POLY
    np.testing.assert_allclose(area, ga, rtol=5e-3)
    np.testing.assert_allclose(cen, gc, atol=5e-3)
    np.testing.assert_allclose(cost.sum(), gh, rtol=2e-3)
    assert coverage_cost(p, POLY) == pytest.approx(cost.sum())


def test_lloyd_flow_decreases_cost_monotonically_to_cvt():
    n = 10
    p0 = np.random.default_rng(1).uniform(0.2, 1.5, (n, 2))
    d = av.Diagram()
    ag = d.add(av.blocks.Integrator(p0), name="ag")
    c = d.add(Coverage(n, POLY, gain=3.0), name="c")
    d.connect(ag.y, c.position)
    d.connect(c.velocity, ag.u)
    res = av.simulate(d, 8.0, dt=0.05, log=[c.cost, ag.y, c.centroid])
    h = res[c.cost]
    assert np.all(np.diff(h) <= 1e-12)
    assert h[-1] < 0.5 * h[0]
    assert np.abs(res[ag.y][-1] - res[c.centroid][-1]).max() < 0.05


def test_one_agent_and_bad_polygon():
    a, cen, cost = cell_moments(np.array([[0.0, 0.0]]), [[-1, -1], [1, -1], [1, 1], [-1, 1]])
    np.testing.assert_allclose(cen, [[0, 0]], atol=1e-12)
    np.testing.assert_allclose(cost, [8 / 3])           # int of x^2+y^2 on [-1,1]^2
    with pytest.raises(av.ParameterError):
        Coverage(3, [[0, 0], [4, 0], [1, 1], [0, 4]])
