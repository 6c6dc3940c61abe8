"""Neighbour-search plans are kept: a plan grown by an overflow is kept for
the diagram's structure (not for one diagram object), so a second
``simulate(backend="jax")`` of the same structure neither re-plans nor
compiles (counted: traces of the program and XLA compilations); plans are
read, set, saved and loaded through a small API; and a rebuilt flocking
diagram (whose law holds a reference to itself) has the key of the first.
Every compiled run is checked against the NumPy engine."""

import os
import warnings

import numpy as np
import pytest

import avblocks as av
from avblocks.core.compiled import cache_info, get_plans, load_plans, save_plans, set_plans
from avblocks.core.compiled import plans as _plans
from avblocks.core.compiled import program as _program
from avblocks.core.compiled.structure import diagram_key, plan_key, stable_digest
from avblocks.environment import Neighbors

if os.environ.get("CI"):
    import jax  # noqa: F401  (in CI the jax extra is installed: never skip)
else:
    pytest.importorskip("jax")
pytestmark = pytest.mark.jax

LOG = ["nb.neighbors"]
KW = dict(t_final=2.0, dt=0.05, solver="euler", log=LOG, log_every=4)


def contracting(n=41, k=4):
    """Agents on a 40 m square pulled to the origin (g.k = -2): they start
    about 6 m apart (a point has a few candidates within 1 m) and end
    bunched (every point has them all)."""
    rng = np.random.default_rng(3)
    d = av.Diagram()
    ag = d.add(av.vehicles.SingleIntegrator(rng.uniform(-20, 20, (n, 2))), name="ag")
    g = d.add(av.blocks.Gain(-2.0), name="g")
    nb = d.add(Neighbors(n, k, radius=1.0, input="position", method="cells"), name="nb")
    d.connect(ag.position, g.u)
    d.connect(g.y, ag.velocity)
    d.connect(ag.position, nb.position)
    return d


@pytest.fixture(autouse=True)
def fresh_book():
    """Each test starts with no kept plan and no compiled program."""
    _plans.forget_plans()
    av.core.compiled.clear_cache()
    yield
    _plans.forget_plans()


def run(d, **kw):
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        res = av.simulate(d, backend="jax", **{**KW, **kw})
    replans = [x for x in w if "re-planned" in str(x.message)]
    return res, len(replans)


def numpy_neighbors(d):
    return np.asarray(av.simulate(d, backend="numpy", progress=False, **KW)["nb.neighbors"])


def test_a_contracting_swarm_run_twice_replans_once_and_compiles_once():
    d1 = contracting()
    res, replans = run(d1)
    assert replans == 1                          # the flock outgrew its t0 plan
    grown = get_plans(d1)["nb/0"]
    assert grown.capacity >= 41                  # all bunched: every point a candidate
    np.testing.assert_array_equal(res["nb.neighbors"], numpy_neighbors(contracting()))
    before = cache_info()
    d2 = contracting()                           # rebuilt: same structure
    res2, replans2 = run(d2)
    after = cache_info()
    assert replans2 == 0
    assert after["traces"] == before["traces"]                 # no trace
    assert after["xla_compiled"] == before["xla_compiled"]     # no XLA compile
    assert after["xla_from_disk"] == before["xla_from_disk"]
    assert get_plans(d2)["nb/0"] == grown
    np.testing.assert_array_equal(res2["nb.neighbors"], res["nb.neighbors"])
    # the same diagram object again, and with another parameter value
    res3, replans3 = run(d2)
    res4, replans4 = run(d2, params={"g.k": -1.0})
    assert replans3 == replans4 == 0
    assert cache_info()["traces"] == before["traces"]
    ref = av.simulate(contracting(), backend="numpy", progress=False,
                      params={"g.k": -1.0}, **KW)
    np.testing.assert_array_equal(res4["nb.neighbors"], ref["nb.neighbors"])


def test_the_plan_key_ignores_plans_and_values_not_structure():
    d1, d2 = contracting(), contracting()
    k1 = plan_key(d1.build())
    av.compile(d1, **{k: v for k, v in KW.items()})          # plans d1's search
    assert plan_key(d1.build()) == k1                        # planned: same plan key
    assert plan_key(d2.build()) == k1
    assert diagram_key(d2.build()) != diagram_key(d1.build())    # d2 not planned yet
    assert stable_digest(k1) == stable_digest(plan_key(d2.build()))
    assert plan_key(contracting(n=42).build()) != k1             # another shape
    assert plan_key(contracting(k=5).build()) != k1              # another K


def test_a_rebuilt_flocking_diagram_has_the_same_structure_key():
    from avblocks.scenarios import flocking
    a, _ = flocking.make_diagram(agents=20, t_final=1.0)
    b, _ = flocking.make_diagram(agents=20, t_final=1.0, seed=4)    # other x0 only
    assert diagram_key(a.build()) == diagram_key(b.build())
    assert stable_digest(plan_key(a.build())) is not None
    # a numeric parameter's value is data, not structure (the law's helper
    # holds a reference to the law)
    law = next(blk for blk in b.build().blocks if type(blk).__name__ == "Flocking")
    law.set_parameter("c1", 2 * law.c1)
    assert diagram_key(a.build()) == diagram_key(b.build())


def test_plans_are_read_set_saved_and_loaded(tmp_path):
    d = contracting()
    assert get_plans(d) == {"nb/0": None}            # not planned yet
    set_plans(d, {"nb/0": {"capacity": 48, "hits": 40}})
    p = get_plans(d)["nb/0"]
    assert (p.capacity, p.hits, p.reach) == (48, 40, 1.0)
    # the book holds it for the structure: a rebuilt diagram compiles with it
    res, replans = run(contracting())
    assert replans == 0                              # room enough from the start
    runner = av.compile(contracting(), **KW)
    assert runner.plans["nb/0"] == p
    np.testing.assert_array_equal(res["nb.neighbors"], numpy_neighbors(contracting()))
    f = tmp_path / "plans.json"
    assert save_plans(f) == 1
    _plans.forget_plans()
    assert get_plans(contracting()) == {"nb/0": None}
    assert load_plans(f) == 1
    assert get_plans(contracting())["nb/0"] == p
    with pytest.raises(av.ParameterError, match="no such neighbour search"):
        set_plans(d, {"law/0": {"capacity": 3}})


def test_grown_plans_are_stored_on_disk_and_read_by_a_new_book(tmp_path):
    _plans.use_plan_store(tmp_path)
    try:
        run(contracting())
        files = list(tmp_path.rglob("*.json"))
        assert len(files) == 1 and files[0].parent.name.startswith("avblocks-")
        _plans.forget_plans()                        # as a new process
        assert get_plans(contracting())["nb/0"].capacity >= 41
        _, replans = run(contracting())
        assert replans == 0
    finally:
        _plans.use_plan_store(None)


def test_cache_dir_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.delenv("AVBLOCKS_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert _program.cache_dir() == tmp_path / "xdg" / "avblocks"
    monkeypatch.setenv("AVBLOCKS_CACHE_DIR", str(tmp_path / "mine"))
    assert _program.cache_dir() == tmp_path / "mine"
    for off in ("0", "off", "OFF", "false"):
        monkeypatch.setenv("AVBLOCKS_CACHE", off)
        assert _program.cache_disabled()
    monkeypatch.setenv("AVBLOCKS_CACHE", "1")
    assert not _program.cache_disabled()


SCENARIO = '''
import numpy as np
import avblocks as av
from avblocks.environment import Neighbors


def make_diagram(n=41):
    rng = np.random.default_rng(3)
    d = av.Diagram()
    ag = d.add(av.vehicles.SingleIntegrator(rng.uniform(-20, 20, (n, 2))), name="ag")
    g = d.add(av.blocks.Gain(-2.0), name="g")
    nb = d.add(Neighbors(n, 4, radius=1.0, input="position", method="cells"), name="nb")
    d.connect(ag.position, g.u)
    d.connect(g.y, ag.velocity)
    d.connect(ag.position, nb.position)
    return d, {"t_final": 2.0, "dt": 0.05, "solver": "euler", "log": ["nb.neighbors"],
               "log_every": 4}
'''


def test_the_cli_reuses_compiled_programs_and_plans_across_processes(tmp_path):
    """Two ``avblocks run ... --backend jax`` processes with one cache folder:
    the first grows the plan (a contracting swarm) and compiles, the second
    reads the plan and the compiled program and compiles nothing."""
    import json
    import subprocess
    import sys
    target = tmp_path / "bunch.py"
    target.write_text(SCENARIO)
    cache = tmp_path / "cache"
    from pathlib import Path
    src = str(Path(av.__file__).resolve().parents[1])      # this avblocks, not another
    env = {**os.environ, "AVBLOCKS_CACHE_DIR": str(cache), "AVBLOCKS_CACHE": "on",
           "PYTHONPATH": os.pathsep.join([src, os.environ.get("PYTHONPATH", "")])}

    def cli(*args, out):
        p = subprocess.run([sys.executable, "-m", "avblocks", *args], env=env,
                           capture_output=True, text=True, timeout=900, cwd=tmp_path)
        assert p.returncode == 0, p.stderr[-2000:]
        summary = json.loads((tmp_path / out / "summary.json").read_text()) \
            if out else None
        return p.stdout, p.stderr, summary

    out1, err1, s1 = cli("run", str(target), "--backend", "jax", "--quiet",
                         "--out", "o1", out="o1")
    assert "re-planned" in err1                          # the t0 plan overflowed
    assert s1["compile"]["compiled"] >= 2 and s1["compile"]["from_disk"] == 0
    assert "compiled program: compiled" in out1
    assert list((cache / "plans").rglob("*.json"))       # the grown plan stored
    assert list((cache / "jax").iterdir())               # the programs stored
    out2, err2, s2 = cli("run", str(target), "--backend", "jax", "--quiet",
                         "--out", "o2", out="o2")
    assert "re-planned" not in err2                      # the stored plan fits
    assert s2["compile"]["compiled"] == 0                # no XLA compile
    assert s2["compile"]["from_disk"] >= 1
    assert "compiled program: from cache" in out2
    import xarray as xr
    with xr.open_dataset(tmp_path / "o1" / "results.nc") as a, \
            xr.open_dataset(tmp_path / "o2" / "results.nc") as b:
        np.testing.assert_array_equal(a["nb.neighbors"].values, b["nb.neighbors"].values)
    out3, _, _ = cli("cache", "clear", out=None)
    assert "cleared" in out3 and not (cache / "jax").exists()
    out4, _, s4 = cli("run", str(target), "--backend", "jax", "--quiet", "--no-cache",
                      "--out", "o4", out="o4")
    assert "cache off" in out4 and s4["compile"]["from_disk"] == 0
    assert not (cache / "jax").exists() and not (cache / "plans").exists()


def test_a_run_in_segments_replans_and_a_stopped_one_says_it_overflowed():
    """With ``progress`` the run goes in segments (core.compiled.segments):
    an overflow re-plans and repeats it as the one-call run does; a run
    stopped from the callback is not repeated, and says it overflowed."""
    calls = []
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        res = av.simulate(contracting(), backend="jax",
                          progress=lambda k, n: calls.append(k), **KW)
    assert len([x for x in w if "re-planned" in str(x.message)]) == 1
    assert calls == [40, 40]                     # the run, then its repetition
    np.testing.assert_array_equal(res["nb.neighbors"], numpy_neighbors(contracting()))
    _plans.forget_plans()
    av.core.compiled.clear_cache()

    def stop(k, n):
        raise KeyboardInterrupt
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        part = av.simulate(contracting(), backend="jax", progress=stop, **KW)
    assert part.meta["interrupted"] and part.meta["overflowed"] == ["nb"]
    assert any("stopped compiled run" in str(x.message) for x in w)
    assert not any("re-planned" in str(x.message) for x in w)


class _Blows(av.Block):
    """Positions that are NaN for agent 2 from t0 on (a broken upstream block)."""

    def __init__(self, n):
        super().__init__()
        self.declare_input("u", (n, 2))
        self.declare_output("y", (n, 2))

    def output(self, t, x, u, xp):
        bad = xp.arange(u["u"].shape[0])[:, None] == 2
        return {"y": xp.where(bad, xp.nan, u["u"])}


def test_planning_from_non_finite_points_names_the_block_or_the_point():
    """A search planned from positions that are NaN at t0 stops before any
    tracing, naming the search's block (its NumPy evaluation at t0 refuses
    them); plan_cells, called directly, names the point (it crashed inside
    NumPy's bincount before)."""
    n = 12
    rng = np.random.default_rng(0)
    d = av.Diagram()
    ag = d.add(av.vehicles.SingleIntegrator(rng.uniform(-5, 5, (n, 2))), name="ag")
    g = d.add(av.blocks.Gain(-1.0), name="g")
    blows = d.add(_Blows(n), name="blows")
    nb = d.add(Neighbors(n, 3, radius=2.0, input="position", method="cells"), name="nb")
    d.connect(ag.position, g.u)
    d.connect(g.y, ag.velocity)
    d.connect(ag.position, blows.u)
    d.connect(blows.y, nb.position)
    with pytest.raises(av.SimulationError) as e:
        av.simulate(d, 0.2, dt=0.05, backend="jax")
    msg = str(e.value)
    assert "block 'nb'" in msg and "t=0" in msg and "finite" in msg
    from avblocks.utility import spatial as sp
    for bad in (np.nan, np.inf, -np.inf):
        p = rng.uniform(0, 5, (20, 2))
        p[7, 1] = bad
        with pytest.raises(av.ParameterError, match="point 7"):
            sp.plan_cells(p, 1.0)


def converging(n=40, t=1.0):
    """Agents 10 m apart on a line, each moving to the origin at the speed
    that takes it there at ``t``: one agent per cell until the last step,
    all of them in one cell at ``t`` (the final sample)."""
    x0 = np.zeros((n, 2))
    x0[:, 0] = 10.0 * np.arange(1, n + 1)
    d = av.Diagram()
    ag = d.add(av.vehicles.SingleIntegrator(x0), name="ag")
    v = d.add(av.blocks.Constant(-x0 / t), name="v")
    nb = d.add(Neighbors(n, 3, radius=1.0, input="position", method="cells"), name="nb")
    d.connect(v.y, ag.velocity)
    d.connect(ag.position, nb.position)
    return d


@pytest.mark.parametrize("log_every", [1, 5])
def test_the_final_samples_search_counts_only_where_it_is_logged(log_every):
    # the final sample (t = 1, after the last step) is where the swarm
    # outgrows its plan; a search nothing logged reads there cannot spoil
    # the results, so a run logging the positions neither raises nor
    # re-plans (the positions are the NumPy engine's); logging the
    # neighbours, the same overflow raises, naming the block
    kw = dict(t_final=1.0, dt=0.1, solver="euler", log_every=log_every)
    for log in (["ag.position"], ["nb.neighbors"]):
        d = converging()
        runner = av.compile(d, log=log, on_overflow="raise", **kw)
        plan_cap = runner.plans["nb/0"].capacity
        assert plan_cap < 40                      # all 40 in one cell is an overflow
        if log == ["ag.position"]:
            res = runner()
            ref = av.simulate(converging(), backend="numpy", progress=False, log=log, **kw)
            np.testing.assert_allclose(res["ag.position"], ref["ag.position"], rtol=0,
                                       atol=1e-12)
            assert np.abs(res["ag.position"][-1]).max() < 1e-9     # all met at the origin
            assert runner.plans["nb/0"].capacity == plan_cap       # not re-planned
        else:
            with pytest.raises(av.SimulationError, match="nb"):
                runner()
