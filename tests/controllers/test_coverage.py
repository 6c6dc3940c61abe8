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


# ---------------------------------------------------------------- grid method
from avblocks.controllers.coverage import density_samples, grid_moments  # noqa: E402

DIAM = float(np.max(np.hypot(*(POLY[:, None] - POLY[None]).transpose(2, 0, 1))))


def test_grid_centroids_converge_to_the_exact_ones():
    """Sampled-grid centroids approach the exact Voronoi centroids as the
    grid is refined; at the default resolution (100) within 0.5 % of the
    polygon's diameter; the sampled mass is the polygon's area exactly."""
    grids = {res: density_samples(POLY, res) for res in (25, 100, 400)}
    for seed in range(3):
        p = np.random.default_rng(seed).uniform(0.5, 3, (7, 2))
        area, cen, cost = cell_moments(p, POLY)
        errs = []
        for res, (q, w) in grids.items():
            m, c, h = grid_moments(p, q, w)
            assert m.sum() == pytest.approx(21.0, rel=1e-12)
            errs.append(np.abs(c - cen).max())
            if res == 100:
                assert errs[-1] < 0.005 * DIAM
                assert h.sum() == pytest.approx(cost.sum(), rel=1e-3)
        assert errs[0] > errs[1] > errs[2]
        assert errs[2] < 0.002


def test_grid_density_weighted_centroid():
    """Density phi = x on the unit square, one agent: centroid
    (int x^2 / int x, 1/2) = (2/3, 1/2)."""
    sq = [[0, 0], [1, 0], [1, 1], [0, 1]]
    q, w = density_samples(sq, 200, density=lambda x, y: x)
    m, c, _ = grid_moments(np.array([[0.2, 0.2]]), q, w)
    assert m[0] == pytest.approx(0.5, rel=1e-12)
    np.testing.assert_allclose(c[0], [2 / 3, 0.5], atol=1e-5)


def test_grid_lloyd_drives_agents_to_the_exact_cvt():
    """The default (grid) controller brings the agents to a configuration
    whose exact Voronoi centroids are the agents themselves (within the
    grid tolerance), the exact cost falling on the way."""
    n = 8
    p0 = np.random.default_rng(4).uniform(0.2, 1.5, (n, 2))
    d = av.Diagram()
    ag = d.add(av.blocks.Integrator(p0), name="ag")
    c = d.add(Coverage(n, POLY, gain=4.0), name="c")
    d.connect(ag.y, c.position)
    d.connect(c.velocity, ag.u)
    res = av.simulate(d, 15.0, dt=0.05, log=[ag.y, c.cost])
    p_end = res[ag.y][-1]
    _, cen, _ = cell_moments(p_end, POLY)
    assert np.abs(cen - p_end).max() < 0.005 * DIAM
    assert coverage_cost(p_end, POLY) < 0.3 * coverage_cost(p0, POLY)
    assert np.all(np.diff(res[c.cost]) <= 1e-9)


def test_voronoi_method_kept_and_refused_by_the_compiled_engine():
    c = Coverage(3, POLY, method="voronoi")
    assert c.traceable is False
    p = np.array([[1.0, 1.0], [3.0, 1.0], [2.0, 3.0]])
    y = c.output(0.0, {}, {"position": p}, np)
    np.testing.assert_allclose(y["centroid"], cell_moments(p, POLY)[1])
    with pytest.raises(av.ParameterError):
        Coverage(3, POLY, method="voronoi", density=lambda x, y: x)
    with pytest.raises(av.ParameterError):
        Coverage(3, POLY, method="exact")


@pytest.mark.jax
def test_grid_coverage_compiled_equals_numpy():
    pytest.importorskip("jax")
    n = 6
    p0 = np.random.default_rng(5).uniform(0.2, 1.5, (n, 2))

    def build():
        d = av.Diagram()
        ag = d.add(av.blocks.Integrator(p0), name="ag")
        c = d.add(Coverage(n, POLY, gain=2.0), name="c")
        d.connect(ag.y, c.position)
        d.connect(c.velocity, ag.u)
        return d

    a = av.simulate(build(), 4.0, dt=0.05, log=["ag.y", "c.cost"])
    b = av.simulate(build(), 4.0, dt=0.05, log=["ag.y", "c.cost"], backend="jax")
    np.testing.assert_allclose(b["ag.y"], a["ag.y"], rtol=0, atol=1e-9)
    np.testing.assert_allclose(b["c.cost"], a["c.cost"], rtol=1e-9)
