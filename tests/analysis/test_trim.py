"""av.trim: equilibria with fixed states, outputs and free inputs; the
residual it reports; the error when there is none."""

import os

import numpy as np
import pytest

import avblocks as av
from avblocks.analysis import TrimError
from avblocks.core.errors import ParameterError

from ._diagrams import consensus_ring

if os.environ.get("CI"):
    import jax  # noqa: F401
else:
    pytest.importorskip("jax")
pytestmark = pytest.mark.jax


def first_order(a=2.0, c=1.0):
    """dx/dt = -a x + c + u (u: a perturbation at s.u1)."""
    d = av.Diagram()
    src = d.add(av.blocks.Constant([[c]]), name="src")
    g = d.add(av.blocks.Gain(-a), name="g")
    x = d.add(av.blocks.Integrator([[0.0]]), name="x")
    s = d.add(av.blocks.Sum("++"), name="s")
    d.connect(x.y, g.u)
    d.connect(g.y, s.u0)
    d.connect(src.y, s.u1)
    d.connect(s.y, x.u)
    return d


def test_the_input_that_holds_a_required_output():
    # x = 3 is an equilibrium when -2 * 3 + 1 + u = 0: u = 5
    tr = av.trim(first_order(), inputs=["s.u1"], outputs={"x.y": [[3.0]]})
    assert tr.success and tr.residual < 1e-12
    np.testing.assert_allclose(tr.inputs["s.u1"], [[5.0]], atol=1e-12)
    np.testing.assert_allclose(tr.states["x.x"], [[3.0]], atol=1e-12)
    np.testing.assert_allclose(tr.outputs["x.y"], [[3.0]], atol=1e-12)
    # and the linearisation there: the input's operating value is carried
    m = av.linearize(first_order(), at=tr, inputs=["s.u1"], outputs=["x.y"])
    np.testing.assert_allclose(m.f0, [0.0], atol=1e-12)
    np.testing.assert_allclose(m.u0, [5.0])


def test_no_equilibrium_is_an_error_with_the_residual_and_the_best_point():
    # two agents of a consensus ring pinned apart: no equilibrium exists
    n = 6
    target = np.full((n, 2), np.nan)
    target[0] = [0.0, 0.0]
    target[3] = [1.0, 0.0]
    with pytest.raises(TrimError, match="no equilibrium found: residual") as e:
        av.trim(consensus_ring(n), fixed={"agents.position": target})
    res = e.value.result
    assert not res.success and res.residual > 1e-3
    # the pinned entries stayed where they were put
    np.testing.assert_array_equal(res.states["agents.position"][[0, 3]],
                                  [[0.0, 0.0], [1.0, 0.0]])
    # leaving the states out of steady= makes any point acceptable
    ok = av.trim(consensus_ring(n), fixed={"agents.position": target}, steady=[])
    assert ok.success and ok.residual == 0.0


def test_bad_specifications_are_named():
    d = first_order()
    with pytest.raises(ParameterError, match="unknown entry"):
        av.trim(d, fixed={"x.y": [[1.0]]})                 # an output, not a state
    with pytest.raises(ParameterError, match="wrong shape"):
        av.trim(d, fixed={"x.x": [1.0, 2.0]})
    with pytest.raises(ParameterError, match="steady names unknown states"):
        av.trim(d, steady=["x.z"])
    with pytest.raises(ParameterError, match="outputs must be a dict"):
        av.trim(d, outputs=["x.y"])
    with pytest.raises(ParameterError, match="finite numbers or NaN"):
        av.trim(d, outputs={"x.y": [[np.inf]]})
    with pytest.raises(TypeError):
        av.trim(d, tolerance=1e-3)                       # unknown keyword
