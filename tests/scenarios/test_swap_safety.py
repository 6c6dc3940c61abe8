"""The swap case study with the default safety filter (the joint barrier
QP, built-in ADMM solver): every agent arrives without a collision for
circle / safety radius ratios 3 to 8, and the compiled run prints the same
outcome numbers as the NumPy run.

Truth: the closest pair is recomputed from the logged positions with
scipy's ``pdist``; arrival from the distance to the antipodal goal.
"""

import json

import numpy as np
import pytest
from scipy.spatial.distance import pdist

import avblocks as av
from avblocks.cli import main
from avblocks.scenarios import swap

# the filter keeps every pair at the safety distance to the ADMM tolerance
# (a relative 1e-10 per step; measured at most 5e-9 m below it)
SAFETY_TOL = 1e-6


def _setting(ratio, circle=5.0):
    """Parameters of a swap at ``circle / safety = ratio``.

    ``n`` agents on a circle are at least ``2 R sin(pi / n)`` apart, so 20
    agents fit at least one safety radius apart only for ratios above 3.2:
    ratio 3 uses 18 agents. Below ratio 5 the angle jitter is reduced so
    that the start is safe (neighbours at least ``(1 - jitter)`` of the
    spacing apart), and the sensing range grows with the safety radius.
    """
    n = 18 if ratio < 3.2 else 20
    safety = circle / ratio
    spacing = 2 * ratio * np.sin(np.pi / n)               # in safety radii
    jitter = min(0.5, round(0.9 * (1 - 1 / spacing), 4))
    return {"agents": n, "radius": circle, "safety": safety, "jitter": jitter,
            "sensing": max(3.0, 3.5 * safety)}


@pytest.mark.slow
@pytest.mark.parametrize("ratio", [3.0, 3.25, 4.0, 5.0, 5.88, 7.0, 8.0])
def test_swap_completes_without_collision_for_ratios_3_to_8(ratio):
    params = _setting(ratio)
    dg, sim = swap.make_diagram(**params)
    res = av.simulate(dg, progress=False, **sim)
    p = np.asarray(res["fleet.position"])
    n = params["agents"]
    start, goal = swap.circle_swap(n, params["radius"], params["jitter"], 1)
    closest = min(pdist(x).min() for x in p)
    assert pdist(start).min() >= params["safety"]          # a safe start
    assert closest >= params["safety"] - SAFETY_TOL, (closest, params["safety"])
    assert np.linalg.norm(p[-1] - goal, axis=1).max() < 0.06  # every agent home
    done = np.asarray(res["drive.done"])
    assert done[-1].all()
    # no long detour: all home by 25 s (10 m straight at <= 1 m/s takes >= 10 s;
    # measured 15.9 to 18.6 s)
    assert res.t[np.argmax(done.all(axis=1))] < 25.0


def _summary(tmp_path, backend, *sets):
    out = tmp_path / backend
    args = ["run", "swap", "--backend", backend, "--out", str(out), "--quiet"]
    for s in sets:
        args += ["--set", s]
    assert main(args) == 0
    return json.loads((out / "summary.json").read_text())


def _numbers(d, path=""):
    """Every int and float in a nested summary, by path."""
    if isinstance(d, dict):
        for k, v in d.items():
            yield from _numbers(v, f"{path}.{k}")
    elif isinstance(d, (list, tuple)):
        for k, v in enumerate(d):
            yield from _numbers(v, f"{path}[{k}]")
    elif isinstance(d, (bool, int, float)) and d is not None:
        yield path, d


@pytest.mark.jax
def test_swap_on_the_compiled_backend_prints_the_numpy_summary(tmp_path):
    pytest.importorskip("jax")
    sets = ("safety=0.85",)                 # Robotarium's ratio, 20 agents, 30 s
    a = _summary(tmp_path, "numpy", *sets)
    b = _summary(tmp_path, "jax", *sets)
    for key in ("status", "agents", "simulated_s", "outcome"):
        assert a[key] == b[key], key
    # the outcome numbers (wall time and real-time factor naturally differ)
    na, nb = dict(_numbers(a["numbers"])), dict(_numbers(b["numbers"]))
    assert na.keys() == nb.keys()
    assert any("at_goal_end" in k for k in na) and any("closest" in k for k in na)
    for k, va in na.items():
        vb = nb[k]
        if isinstance(va, (bool, int)) and not isinstance(va, float):
            assert va == vb, k
        else:
            assert vb == pytest.approx(va, rel=1e-4), k
    assert na[".at_goal_end"] == 20


@pytest.mark.jax
def test_swap_sweep_as_a_compiled_ensemble_equals_the_numpy_sweep(tmp_path):
    pytest.importorskip("jax")
    from avblocks.sweep import Study
    common = ["sweep", "swap", "--grid", "safety=0.6,0.85", "--seeds", "2",
              "--set", "agents=6", "--set", "t_final=20", "--quiet"]
    assert main(common + ["--ensemble", "--out", str(tmp_path / "e.zarr")]) == 0
    assert main(common + ["--out", str(tmp_path / "n.zarr")]) == 0
    a = Study.open(tmp_path / "e.zarr").to_xarray()
    b = Study.open(tmp_path / "n.zarr").to_xarray()
    for k in ("min_gap", "done_fraction", "time_to_done"):
        np.testing.assert_allclose(np.asarray(a[k], float), np.asarray(b[k], float),
                                   rtol=1e-9, err_msg=k)
    assert np.all(np.asarray(a["done_fraction"]) == 1.0)
    assert np.all(np.asarray(a["min_gap"]) >= np.asarray(a["safety"])[:, None] - SAFETY_TOL)
