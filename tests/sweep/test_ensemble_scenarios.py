"""``avblocks sweep NAME --ensemble`` on the built-in interacting scenarios:
each case's metrics from the vmapped JAX ensemble equal the same case run
alone on the NumPy engine (the non-ensemble sweep's computation), for
every built-in case study with interaction."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("jax")
pytest.importorskip("zarr")

import avblocks as av  # noqa: E402
from avblocks.sweep.ensemble import compute_group  # noqa: E402
from avblocks.sweep.runner import compute_case  # noqa: E402

pytestmark = [pytest.mark.sweep, pytest.mark.jax]

SMALL = {
    "flocking": {"agents": 8, "t_final": 1.0},
    "swap": {"agents": 6, "t_final": 1.0},
    "formation": {"t_final": 1.0},
    "waypoints": {"agents": 4, "simulation.t_final": 1.0},
    "nest": {"agents": 40, "t_final": 1.0},
    "honeybee": {"agents": 40, "t_final": 2.0},
}


@pytest.mark.parametrize("name", sorted(SMALL))
def test_ensemble_metrics_equal_numpy_runs(name):
    spec, _ = av.sweep.make_spec(name, seeds=2, fixed=SMALL[name], ensemble=True)
    got = compute_group(spec, [0, 1])
    for cid in (0, 1):
        assert not isinstance(got[cid], Exception), got[cid]
        ens, _ = got[cid]
        ref, _ = compute_case(spec, cid)
        assert set(ens) == set(ref)
        for k in ref:
            np.testing.assert_allclose(np.asarray(ens[k], float), np.asarray(ref[k], float),
                                       rtol=1e-7, atol=1e-9, equal_nan=True, err_msg=k)


@pytest.mark.slow          # a local Dask cluster and a JAX compile in its worker
def test_cli_flocking_sweep_ensemble(tmp_path, capsys):
    from avblocks.cli import main
    out = tmp_path / "f.zarr"
    rc = main(["sweep", "flocking", "--seeds", "2", "--set", "agents=8", "--set",
               "t_final=1", "--ensemble", "--workers", "1", "--out", str(out),
               "--no-plot", "--quiet"])
    assert rc == 0
    assert "2 done, 0 failed" in capsys.readouterr().out


def test_final_order_from_velocity_when_no_order_is_logged():
    v = np.array([[[1.0, 0.0], [0.0, 1.0]], [[3.0, 4.0], [-3.0, 4.0]]])   # (T, N, 2)
    res = av.Results(np.array([0.0, 1.0]), {"flock.velocity": v})
    # |(0, 8)| / (5 + 5) = 0.8 at the last sample
    assert av.sweep.METRICS["final_order"](res) == pytest.approx(0.8, rel=1e-15)
    res2 = av.Results(np.array([0.0, 1.0]), {"view.order": np.array([0.1, 0.7]),
                                             "flock.velocity": v})
    assert av.sweep.METRICS["final_order"](res2) == 0.7
