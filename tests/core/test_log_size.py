"""The log-size cap: an explicit log_every that does not fit is refused
with the log_every that does; by default a too-big log is decimated to fit
(so 30,000 agents need nothing but N changed)."""

import math

import numpy as np
import pytest

import avblocks as av


def fleet(n):
    d = av.Diagram()
    f = d.add(av.vehicles.Unicycle(pose0=np.zeros((n, 3))), name="fleet")
    c = d.add(av.blocks.Constant(np.tile([1.0, 0.0], (n, 1))), name="c")
    d.connect(c.y, f.cmd)
    return d, f


def test_error_names_the_log_every_that_fits():
    d, f = fleet(10)
    # 1000 steps, 10 x 3 float64 = 240 bytes a sample; 24,000 bytes: 100 samples
    with pytest.raises(av.ParameterError, match=r"log_every=11 fits") as e:
        av.simulate(d, 10.0, dt=0.01, log=[f.pose], log_every=1, max_log_bytes=24_000)
    assert "0.00 GB" in str(e.value) or "GB" in str(e.value)
    # and it does fit, while one less does not
    res = av.simulate(d, 10.0, dt=0.01, log=[f.pose], log_every=11, max_log_bytes=24_000)
    assert res["fleet.pose"].nbytes <= 24_000 and len(res.t) == 1000 // 11 + 1
    with pytest.raises(av.ParameterError):
        av.simulate(d, 10.0, dt=0.01, log=[f.pose], log_every=10, max_log_bytes=24_000)


def test_default_decimates_to_fit_with_a_warning():
    d, f = fleet(10)
    with pytest.warns(UserWarning, match="logging one step in 11"):
        res = av.simulate(d, 10.0, dt=0.01, log=[f.pose], max_log_bytes=24_000)
    assert res.meta["log_every"] == 11
    np.testing.assert_allclose(res.t, np.arange(0, 1001, 11) * 0.01)
    np.testing.assert_allclose(res["fleet.pose"][:, :, 0], res.t[:, None] * np.ones(10))


def test_thirty_thousand_agents_with_the_default_cap():
    """The README's case (N = 30,000, dt = 0.01, 30 s: 2.16 GB at every
    step): the cap picks log_every = 2. Run for a short time with the same
    per-step size: 1 s is 101 samples; cap scaled by 1/30 keeps the ratio."""
    n, steps = 30_000, 3000
    per = n * 3 * 8
    assert (steps + 1) * per > 2 * 1024**3                 # the README's log is too big
    from avblocks.core.simulator import log_every_that_fits
    k = log_every_that_fits(per, steps, 2 * 1024**3)
    assert k == 2 and (steps // k + 1) * per <= 2 * 1024**3
    d, f = fleet(n)
    cap = math.ceil(per * 60)                              # 60 samples of 30,000 poses
    with pytest.warns(UserWarning, match="logging one step in 2 "):
        res = av.simulate(d, 1.0, dt=0.01, log=[f.pose], max_log_bytes=cap)
    assert res["fleet.pose"].shape == (51, n, 3)
    np.testing.assert_allclose(res["fleet.pose"][-1, :, 0], 1.0)
