"""Compiled once, across processes (avblocks.core.compiled.persist): a
second process of the same run compiles nothing, through the command line
and through ``simulate`` (counted with JAX's own monitoring events: XLA
compile requests less persistent-cache hits); ``cache=False`` and
``AVBLOCKS_CACHE=off`` opt out; the cache folder is checked before use and a
damaged or foreign entry in it is ignored with a warning, never trusted."""

import json
import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import avblocks as av
from avblocks.core.compiled import persist
from avblocks.core.compiled import plans as _plans

if os.environ.get("CI"):
    import jax  # noqa: F401  (in CI the jax extra is installed: never skip)
else:
    pytest.importorskip("jax")
pytestmark = pytest.mark.jax

SRC = str(Path(av.__file__).resolve().parents[1])      # this avblocks, not another

#: a child process: counts XLA compiles with JAX's monitoring events (every
#: compile request is a backend-compile event; a read from the persistent
#: cache is also a cache-hit event), runs ``RUN`` and prints the counts
CHILD = '''
import json, sys, warnings
import jax.monitoring as mon
count = {"requests": 0, "hits": 0}
def on_duration(event, secs, **kw):
    if event == "/jax/core/compile/backend_compile_duration":
        count["requests"] += 1
def on_event(event, **kw):
    if event == "/jax/compilation_cache/cache_hits":
        count["hits"] += 1
mon.register_event_duration_secs_listener(on_duration)
mon.register_event_listener(on_event)
out = {}
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
%s
count["compiles"] = count["requests"] - count["hits"]
count["warnings"] = [str(w.message)[:300] for w in caught]
count.update(out)
print("COUNTS " + json.dumps(count))
'''

CLI = '''
    from avblocks.cli import main
    out["rc"] = main(%r)
'''

SIMULATE = '''
    import numpy as np
    import avblocks as av
    from avblocks.scenarios.targets import load_any, parse_overrides
    d, sim, name, movie = load_any("flocking", parse_overrides(%r), None)
    sim["backend"] = "jax"
    res = av.simulate(d, progress=False, **sim%s)
    np.save(%r, np.asarray(res["flock.position"][-1]))
'''


def child(body, env, cwd):
    code = CHILD % body
    p = subprocess.run([sys.executable, "-c", code], env=env, cwd=cwd, timeout=900,
                       capture_output=True, text=True)
    assert p.returncode == 0, p.stderr[-3000:]
    line = [x for x in p.stdout.splitlines() if x.startswith("COUNTS ")][-1]
    return json.loads(line[7:]), p.stderr


def environment(cache, **more):
    env = {k: v for k, v in os.environ.items() if k not in ("AVBLOCKS_CACHE",)}
    env.update(AVBLOCKS_CACHE_DIR=str(cache),
               PYTHONPATH=os.pathsep.join([SRC, os.environ.get("PYTHONPATH", "")]),
               **more)
    return env


SETS = ["agents=500", "spread=200", "t_final=10"]


@pytest.mark.slow
def test_the_contracting_flock_compiles_nothing_in_a_second_process(tmp_path):
    """The issue's run: ``avblocks run flocking --backend jax --set agents=500
    --set spread=200 --set t_final=10`` in a fresh cache grows its plan (the
    flock contracts: re-planned) and compiles; the same command in a second
    process, and the same run through ``simulate`` in a fresh Python
    process, compile nothing (the grown plan is read, then the program),
    and give the first run's positions to the bit."""
    cache = tmp_path / "cache"
    env = environment(cache)
    argv = ["run", "flocking", "--backend", "jax", "--quiet"]
    for s in SETS:
        argv += ["--set", s]
    first, err1 = child(CLI % (argv + ["--out", str(tmp_path / "o1")]), env, tmp_path)
    assert first["rc"] == 0
    assert "re-planned" in err1 + " ".join(first["warnings"])     # the plan grew
    assert first["compiles"] >= 2                    # the t0 plan's and the grown one's
    second, err2 = child(CLI % (argv + ["--out", str(tmp_path / "o2")]), env, tmp_path)
    assert second["rc"] == 0
    assert second["compiles"] == 0, second           # nothing compiled...
    assert second["hits"] >= 1                       # ...the program read from the cache
    assert "re-planned" not in err2 + " ".join(second["warnings"])
    summary = json.loads((tmp_path / "o2" / "summary.json").read_text())
    assert summary["compile"]["compiled"] == 0 and summary["compile"]["from_disk"] >= 1
    import xarray as xr
    with xr.open_dataset(tmp_path / "o1" / "results.nc") as a, \
            xr.open_dataset(tmp_path / "o2" / "results.nc") as b:
        p1 = a["flock.position"].values
        np.testing.assert_array_equal(p1, b["flock.position"].values)
    third, err3 = child(SIMULATE % (SETS, "", str(tmp_path / "p3.npy")), env, tmp_path)
    assert third["compiles"] == 0, third
    assert "re-planned" not in err3 + " ".join(third["warnings"])
    np.testing.assert_array_equal(np.load(tmp_path / "p3.npy"), p1[-1])


SMALL = '''
    import numpy as np
    import avblocks as av
    from avblocks.environment import Neighbors
    rng = np.random.default_rng(3)
    d = av.Diagram()
    ag = d.add(av.vehicles.SingleIntegrator(rng.uniform(-20, 20, (41, 2))), name="ag")
    g = d.add(av.blocks.Gain(-2.0), name="g")
    nb = d.add(Neighbors(41, 4, radius=1.0, input="position", method="cells"), name="nb")
    d.connect(ag.position, g.u)
    d.connect(g.y, ag.velocity)
    d.connect(ag.position, nb.position)
    res = av.simulate(d, 2.0, dt=0.05, solver="euler", log=["nb.neighbors"], log_every=4,
                      backend="jax"%s)
    np.save(%r, np.asarray(res["nb.neighbors"]))
'''


def files(folder):
    return sorted(str(p.relative_to(folder)) for p in Path(folder).rglob("*")
                  if p.is_file()) if Path(folder).exists() else []


def test_simulate_keeps_programs_and_plans_by_default_and_opts_out(tmp_path):
    """``simulate(backend="jax")`` in a fresh process uses the cache folder
    by default: a contracting swarm grows its plan in the first process,
    the second reads plan and program and compiles nothing; ``cache=False``
    and ``AVBLOCKS_CACHE=off`` compile and write nothing to the folder.
    Every run gives the NumPy engine's neighbours."""
    cache = tmp_path / "cache"
    env = environment(cache)
    out = str(tmp_path / "n.npy")
    first, err1 = child(SMALL % ("", out), env, tmp_path)
    assert "re-planned" in " ".join(first["warnings"])
    assert first["compiles"] >= 2
    kept = files(cache)
    assert any(f.startswith("plans/") for f in kept)
    assert any(f.startswith("jax/") for f in kept)
    second, _ = child(SMALL % ("", out), env, tmp_path)
    assert second["compiles"] == 0 and second["hits"] >= 1, second
    assert not any("re-planned" in w for w in second["warnings"])
    got = np.load(out)
    from avblocks.environment import Neighbors
    rng = np.random.default_rng(3)
    d = av.Diagram()
    ag = d.add(av.vehicles.SingleIntegrator(rng.uniform(-20, 20, (41, 2))), name="ag")
    g = d.add(av.blocks.Gain(-2.0), name="g")
    nb = d.add(Neighbors(41, 4, radius=1.0, input="position", method="cells"), name="nb")
    d.connect(ag.position, g.u)
    d.connect(g.y, ag.velocity)
    d.connect(ag.position, nb.position)
    ref = av.simulate(d, 2.0, dt=0.05, solver="euler", log=["nb.neighbors"], log_every=4,
                      progress=False)
    np.testing.assert_array_equal(got, ref["nb.neighbors"])
    # a damaged program entry: JAX warns, compiles, and the run is right
    for f in (cache / "jax").rglob("*"):
        if f.is_file() and "cache" in f.name:
            f.write_bytes(b"not an executable" * 10)
    damaged, err = child(SMALL % ("", out), env, tmp_path)
    assert damaged["compiles"] >= 1 and damaged["hits"] == 0, damaged
    assert "Error reading persistent compilation cache entry" in \
        err + " ".join(damaged["warnings"])
    np.testing.assert_array_equal(np.load(out), ref["nb.neighbors"])
    kept = files(cache)
    # opting out: the same run compiles (programs and the plan not read) and
    # leaves the folder as it was
    # (the two opt-outs run side by side: neither touches the folder)
    from concurrent.futures import ThreadPoolExecutor
    out2 = str(tmp_path / "n2.npy")
    with ThreadPoolExecutor(2) as pool:
        a = pool.submit(child, SMALL % (", cache=False", out), env, tmp_path)
        b = pool.submit(child, SMALL % ("", out2), environment(cache, AVBLOCKS_CACHE="off"),
                        tmp_path)
        (off, _), (off2, _) = a.result(), b.result()
    assert off["compiles"] >= 2 and off["hits"] == 0
    assert "re-planned" in " ".join(off["warnings"])
    assert off2["compiles"] >= 2 and off2["hits"] == 0
    np.testing.assert_array_equal(np.load(out2), ref["nb.neighbors"])
    assert files(cache) == kept
    np.testing.assert_array_equal(np.load(out), ref["nb.neighbors"])


def contracting(n=41):
    rng = np.random.default_rng(3)
    d = av.Diagram()
    ag = d.add(av.vehicles.SingleIntegrator(rng.uniform(-20, 20, (n, 2))), name="ag")
    g = d.add(av.blocks.Gain(-2.0), name="g")
    nb = d.add(av.environment.Neighbors(n, 4, radius=1.0, input="position",
                                        method="cells"), name="nb")
    d.connect(ag.position, g.u)
    d.connect(g.y, ag.velocity)
    d.connect(ag.position, nb.position)
    return d


KW = dict(t_final=2.0, dt=0.05, solver="euler", log=["nb.neighbors"], log_every=4)


def _run(d, **kw):
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        res = av.simulate(d, backend="jax", **{**KW, **kw})
    return res, [str(x.message) for x in w]


@pytest.fixture
def store(tmp_path):
    """A plan store of the test's own (the tests' default is memory only)."""
    folder = _plans.use_plan_store(tmp_path / "plans")
    yield folder
    _plans.use_plan_store(False)


def test_damaged_or_foreign_plan_files_are_ignored_with_a_warning(store):
    """Each kind of bad plan file is read as data and refused: the search
    is planned afresh (one re-plan, as with no file) and the run gives the
    NumPy engine's neighbours. Nothing in a file is executed."""
    ref = av.simulate(contracting(), backend="numpy", progress=False, **KW)["nb.neighbors"]
    res, msgs = _run(contracting())
    (f,) = list(store.glob("*.json"))
    good = json.loads(f.read_text())
    assert good["plans"]["nb/0"]["capacity"] >= 41
    plan = good["plans"]["nb/0"]
    bad = {
        "not json": "{ this is not json",
        "a pickle": b"\x80\x04\x95\x10\x00\x00\x00\x00\x00\x00\x00\x8c\x02os\x94.",
        "another version": json.dumps({**good, "versions": "avblocks-0.0.1_jax-0.0.1"}),
        "wrong types": json.dumps({**good, "plans": {"nb/0": {**plan, "capacity": "48"}}}),
        "unknown field": json.dumps({**good, "plans": {"nb/0": {**plan, "code": "x"}}}),
        "negative": json.dumps({**good, "plans": {"nb/0": {**plan, "hits": -3}}}),
        "too big": json.dumps({**good, "plans": {"nb/0": {**plan, "capacity": 10**9}}}),
        "other reach": json.dumps({**good, "plans": {"nb/0": {**plan, "reach": 3.0}}}),
    }
    for why, text in bad.items():
        _plans.forget_plans()           # the book forgets: the file is read again
        if isinstance(text, bytes):
            f.write_bytes(text)
        else:
            f.write_text(text)
        res, msgs = _run(contracting())
        assert any("ignored" in m for m in msgs), (why, msgs)
        assert any("re-planned" in m for m in msgs), why      # planned afresh
        np.testing.assert_array_equal(res["nb.neighbors"], ref)


def test_a_cache_folder_others_may_write_to_is_not_used(tmp_path):
    """A folder group or others may write to (a program read from it is
    machine code that runs) is refused with a warning; the run compiles
    without it and writes nothing there."""
    root = tmp_path / "shared"
    root.mkdir(mode=0o777)
    os.chmod(root, 0o777)
    with pytest.warns(RuntimeWarning, match="not used: others may write"):
        assert persist.usable(root) is None
    own = tmp_path / "own"
    assert persist.usable(own) == own
    assert (own.stat().st_mode & 0o777) == 0o700
    with pytest.raises(av.ParameterError, match="cache"):
        persist.resolve(3)


def test_the_cache_folder_is_the_platforms(monkeypatch, tmp_path):
    import platformdirs
    monkeypatch.delenv("AVBLOCKS_CACHE_DIR", raising=False)
    monkeypatch.delenv("AVBLOCKS_CACHE", raising=False)
    assert persist.cache_dir() == Path(platformdirs.user_cache_dir("avblocks",
                                                                    appauthor=False))
    monkeypatch.setenv("AVBLOCKS_CACHE_DIR", str(tmp_path / "mine"))
    assert persist.resolve(None) == tmp_path / "mine"
    assert persist.resolve(True) == tmp_path / "mine"
    assert persist.resolve(False) is None
    assert persist.resolve(str(tmp_path / "x")) == tmp_path / "x"
    monkeypatch.setenv("AVBLOCKS_CACHE", "off")
    assert persist.resolve(None) is None
    assert persist.resolve(True) == tmp_path / "mine"     # the argument wins


def test_load_plans_refuses_what_is_not_a_plans_file(tmp_path):
    f = tmp_path / "p.json"
    for text in ("[]", '{"structures": {"abc": {"nb/0": {"capacity": "x"}}}}',
                 '{"structures": 5}', "not json"):
        f.write_text(text)
        with pytest.raises(av.ParameterError, match="not a plans file"):
            _plans.load_plans(f)


TINY = '''
    import jax
    if %r:                     # the user's own cache, keeping every program
        jax.config.update("jax_compilation_cache_dir", %r)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    import numpy as np
    import avblocks as av
    d = av.Diagram()
    c = d.add(av.blocks.Constant([[1.0]]), name="c")
    i = d.add(av.blocks.Integrator([[0.0]]), name="i")
    d.connect(c.y, i.u)
    out["y"] = float(av.simulate(d, 1.0, dt=0.1, log=["i.y"], backend="jax")["i.y"][-1, 0, 0])
    out["jax_dir"] = jax.config.jax_compilation_cache_dir
'''


def test_a_jax_cache_folder_set_by_the_user_is_kept(tmp_path):
    """Whoever set JAX's persistent cache folder first keeps it: the
    programs go there, not into avblocks' folder; without one, avblocks
    points JAX at ``<cache>/jax``."""
    ours, mine = tmp_path / "ours", tmp_path / "mine"
    env = environment(ours)
    got, _ = child(TINY % (True, str(mine)), env, tmp_path)
    assert abs(got["y"] - 1.0) < 1e-12
    assert got["jax_dir"] == str(mine)
    assert files(mine) and not [f for f in files(ours) if f.startswith("jax/")]
    got, _ = child(TINY % (False, ""), env, tmp_path)
    assert got["jax_dir"] == str(ours / "jax")
    assert [f for f in files(ours) if f.startswith("jax/")]


def test_two_processes_share_the_cache_folder_at_once(tmp_path):
    """Two processes of the same run started together on one cache folder
    (JAX's reads and writes under a file lock, plan files written whole):
    both give the NumPy engine's neighbours, with no damaged entry read; a
    third then compiles nothing."""
    cache = tmp_path / "cache"
    env = environment(cache)
    code = [CHILD % (SMALL % ("", str(tmp_path / f"n{i}.npy"))) for i in (0, 1)]
    procs = [subprocess.Popen([sys.executable, "-c", c], env=env, cwd=tmp_path,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for c in code]
    outs = [p.communicate(timeout=900) for p in procs]
    for p, (o, e) in zip(procs, outs):
        assert p.returncode == 0, e[-3000:]
        assert "Error reading persistent compilation cache" not in o + e
    a, b = np.load(tmp_path / "n0.npy"), np.load(tmp_path / "n1.npy")
    np.testing.assert_array_equal(a, b)
    third, _ = child(SMALL % ("", str(tmp_path / "n2.npy")), env, tmp_path)
    assert third["compiles"] == 0, third
    np.testing.assert_array_equal(np.load(tmp_path / "n2.npy"), a)
    ref = av.simulate(contracting(), backend="numpy", progress=False, **KW)["nb.neighbors"]
    np.testing.assert_array_equal(a, ref)
