"""nest and honeybee on the compiled engine: `avblocks run NAME --backend jax`
prints the same summary.json numbers as the NumPy run (the random walks and
the gossip draw from the same counter-based stream in both engines; the
compiled engine plans the gossip's neighbour search and checks it never
overflowed, so the compiled run is exact)."""

import json

import numpy as np
import pytest

from avblocks.cli import main

jax = pytest.importorskip("jax")


def _summary(tmp_path, name, backend, sets, t_final):
    out = tmp_path / f"{name}_{backend}"
    argv = ["run", name, "--quiet", "--backend", backend, "--out", str(out),
            "--t-final", str(t_final)]
    for s in sets:
        argv += ["--set", s]
    assert main(argv) == 0
    return json.loads((out / "summary.json").read_text()), out


def _same_numbers(a, b):
    assert a["outcome"] == b["outcome"]
    assert a["numbers"].keys() == b["numbers"].keys()
    for k, v in a["numbers"].items():
        w = b["numbers"][k]
        if v is None or isinstance(v, (int, bool)):
            assert v == w, k
        else:
            assert w == pytest.approx(v, rel=1e-4), k


def test_nest_compiles_and_matches_numpy(tmp_path):
    sets = ["agents=120", "p_loss=0.2"]
    ref, out = _summary(tmp_path, "nest", "numpy", sets, 30.0)
    got, _ = _summary(tmp_path, "nest", "jax", sets, 30.0)
    _same_numbers(ref, got)
    assert ref["numbers"]["informed_at_end"] > ref["numbers"]["scouts"]   # it spread


def test_honeybee_compiles_and_matches_numpy(tmp_path):
    # seed 4: found at ~75 s, a scout home at ~106 s, all 100 know at ~144 s
    sets = ["agents=100", "seed=4", "log_every=1"]
    ref, out = _summary(tmp_path, "honeybee", "numpy", sets, 150.0)
    got, _ = _summary(tmp_path, "honeybee", "jax", sets, 150.0)
    _same_numbers(ref, got)
    nums = ref["numbers"]
    assert None not in (nums["detected_s"], nums["returned_s"], nums["all_informed_s"])


@pytest.mark.slow
@pytest.mark.parametrize("name", ["nest", "honeybee"])
def test_full_case_studies_match_numpy(tmp_path, name):
    t_final = {"nest": 100.0, "honeybee": 250.0}[name]
    ref, out = _summary(tmp_path, name, "numpy", [], t_final)
    got, _ = _summary(tmp_path, name, "jax", [], t_final)
    _same_numbers(ref, got)


def test_nest_ensemble_of_seeds_equals_numpy_runs():
    import avblocks as av
    from avblocks.scenarios import nest
    d, sim = nest.make_diagram(agents=40, t_final=5.0, p_loss=0.3)
    kw = {k: v for k, v in sim.items() if k != "seed"}
    runner = av.compile(d, **kw)
    seeds = [3, 4, 5]
    ens = runner.ensemble(seeds=seeds)
    counts = []
    for r, s in enumerate(seeds):
        ref = av.simulate(d, seed=s, progress=False, **kw)
        np.testing.assert_array_equal(ens.run(r)["gossip.informed"], ref["gossip.informed"])
        assert np.max(np.abs(ens.run(r)["bees.pose"] - ref["bees.pose"])) < 1e-9
        counts.append(int(ref["gossip.informed"][-1].sum()))
    assert len(set(counts)) > 1 or not np.array_equal(       # the seeds differ
        ens.run(0)["bees.pose"], ens.run(1)["bees.pose"])


@pytest.mark.slow          # a local Dask cluster, JAX compiling in its worker
def test_nest_ensemble_sweep_matches_the_numpy_sweep(tmp_path):
    import avblocks as av
    kw = dict(grid={"p_loss": [0.0, 0.6]}, seeds=2, fixed={"agents": 40, "t_final": 6.0},
              workers=1, summary=False, plot=False)
    a = av.sweep("nest", out=str(tmp_path / "np.zarr"), **kw).to_xarray()
    b = av.sweep("nest", out=str(tmp_path / "ens.zarr"), ensemble=True, **kw).to_xarray()
    assert set(a.data_vars) == set(b.data_vars)
    nums = [v for v in a.data_vars if a[v].dtype.kind in "fiub" and "wall" not in v]
    assert "done_fraction" in nums
    for v in nums:
        np.testing.assert_allclose(b[v].values, a[v].values, rtol=1e-9, err_msg=v)
