"""Sweep stores from someone else, and resumes in every order (issue 42).

- A store's definition never runs code: a ``.py`` scenario is stored by its
  path and SHA-256 and run on resume only when the file there has that
  hash; a definition carrying scenario text that would write a marker
  file, a changed file, a path out of the folder, a built-in name that is a
  path, junk types and huge values are all refused with a
  :class:`SweepError` naming what is wrong, and the marker never appears.
- A sweep whose cases succeed, fail or are interrupted, then resumed with
  cases that succeed or fail, writes a complete dataset: ``xarray``'s own
  reader finds every case's status, error text and metric, and the
  metrics equal the closed form ``x(t) = g + (x0 - g) exp(-k t)``.

The sweep runs on a real Dask LocalCluster (2 worker processes on
127.0.0.1), the only engine sweeps have (ensembles are a variant of its
tasks, tested in test_sweep.py).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

import avblocks as av

if not os.environ.get("CI"):
    pytest.importorskip("dask.distributed")
    pytest.importorskip("zarr")
import xarray as xr  # noqa: E402
import zarr  # noqa: E402
from dask.distributed import Client, LocalCluster  # noqa: E402

from avblocks.sweep import Study, SweepError  # noqa: E402
from avblocks.sweep import store as sweep_store  # noqa: E402

pytestmark = pytest.mark.sweep

HERE = Path(__file__).parent
SCEN = str(HERE / "goal_scenario.py")
FIXED = {"n": 3, "t_final": 0.5}
GRID = {"goal": [0.0, 1.0]}
LONG = "a failure with a long message " * 25          # ~700 characters of error text


def final_x(res):                   # agent 0's final x: the closed form checks it
    return float(res["fleet.position"][-1, 0, 0])


def fails_short(res):
    raise RuntimeError("no")


def fails_long(res):
    raise RuntimeError(LONG)


def truth(goal, seed=0, k=1.0, t=0.5):
    x0 = np.random.default_rng(seed).uniform(-1.0, 1.0, (3, 2))[0, 0]
    return goal + (x0 - goal) * np.exp(-k * t)


@pytest.fixture(scope="module")
def client():
    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                           host="127.0.0.1", dashboard_address=None,
                           scheduler_kwargs={"dashboard_address": "127.0.0.1:0",
                                             "dashboard": False}, silence_logs=50)
    c = Client(cluster)
    yield c
    c.close()
    cluster.close()


# ------------------------------------------------------------ resume orders
def _first_run(out, client, first, interruption):
    """Case 0 done or failed; case 1 left missing: interrupted before the
    sweep finished (no dataset), or after (a dataset on disk that says
    otherwise, as a resumed store has)."""
    metric = final_x if first == "done" else fails_short
    if interruption == "no dataset":
        from avblocks.sweep.runner import execute
        spec, _ = av.sweep.make_spec(SCEN, GRID, seeds=1, metrics={"m": metric},
                                     fixed=FIXED)
        sweep_store.create_store(out, spec.data)
        execute(spec, [0], str(out), client)          # then Ctrl-C: nothing more
    else:
        av.sweep(SCEN, grid=GRID, seeds=1, metrics={"m": metric}, fixed=FIXED,
                 out=str(out), scheduler=client, summary=False, plot=False)
        shutil.rmtree(out / "cases" / "c0000001")     # the dataset still has it


def _check_dataset(out, statuses):
    """The dataset at the store's root, read by xarray alone."""
    ds = xr.open_zarr(str(out))
    got = [str(s) for s in ds["status"].values.ravel()]
    assert got == statuses
    recs = Study(out).records()
    for cid, st in enumerate(statuses):
        err = str(ds["error"].values.ravel()[cid])
        assert err == recs[cid]["error"]                       # whole, not cut to a width
        m = float(ds["m"].values.ravel()[cid])
        if st == "done":
            assert m == pytest.approx(truth(GRID["goal"][cid]), abs=1e-6)
            assert err == ""
        else:
            assert np.isnan(m) and err.startswith("RuntimeError: ")
    return ds


@pytest.mark.parametrize("interruption", ["no dataset", "stale dataset"])
@pytest.mark.parametrize("first", ["done", "failed"])
@pytest.mark.parametrize("then", ["done", "failed"])
def test_resume_writes_a_complete_dataset_in_every_order(client, tmp_path, first,
                                                         interruption, then):
    out = tmp_path / "s.zarr"
    _first_run(out, client, first, interruption)
    assert Study(out).counts()["missing"] == 1
    study = av.sweep.resume(str(out), scheduler=client, summary=False, plot=False,
                            metrics={"m": final_x if then == "done" else fails_long},
                            scenario=SCEN)
    assert study.last_run["ran"] == 1 and study.counts()["missing"] == 0
    ds = _check_dataset(out, [first, then])
    if then == "failed":
        assert LONG.strip() in str(ds["error"].values.ravel()[1])
    # retrying the failed cases with a metric that works rewrites the dataset
    again = av.sweep.resume(str(out), scheduler=client, summary=False, plot=False,
                            retry_failed=True, metrics={"m": final_x}, scenario=SCEN)
    assert again.last_run["ran"] == [first, then].count("failed")
    _check_dataset(out, ["done", "done"])


def test_resume_over_a_dataset_an_older_avblocks_wrote(client, tmp_path):
    """Fixed-width texts on disk ('<U4' for 'done'), as avblocks 0.3 wrote
    them: the resumed dataset replaces them."""
    out = tmp_path / "old.zarr"
    _first_run(out, client, "done", "stale dataset")
    ds = xr.open_zarr(str(out)).load()
    old = ds.assign(status=ds["status"].astype("<U4"), error=ds["error"].astype("<U1"))
    root = zarr.open_group(str(out), mode="r+")
    keep = dict(root.attrs)
    for name in list(root.array_keys()):
        del root[name]
    old.to_zarr(str(out), mode="a", consolidated=False)
    zarr.open_group(str(out), mode="r+").attrs.update(keep)
    assert zarr.open_group(str(out))["status"].dtype == np.dtype("<U4")
    av.sweep.resume(str(out), scheduler=client, summary=False, plot=False,
                    metrics={"m": fails_long}, scenario=SCEN)
    _check_dataset(out, ["done", "failed"])


# ------------------------------------------------------------ crafted stores
MARKER_CODE = """
from pathlib import Path
Path({marker!r}).write_text("pwned")
"""


def _store(tmp_path, scenario=SCEN, cases=(0,)):
    """A real store of the 2-case sweep with ``cases`` done (written here,
    without a cluster) and its definition as JSON."""
    from avblocks.sweep.runner import run_case
    out = tmp_path / "crafted.zarr"
    spec, _ = av.sweep.make_spec(scenario, GRID, seeds=1, metrics=["min_gap"], fixed=FIXED)
    sweep_store.create_store(out, spec.data)
    for cid in cases:
        run_case(spec.data, cid, str(out))
    root = zarr.open_group(str(out), mode="r+")
    return out, json.loads(root.attrs["avblocks_sweep"])


def _deep(n):
    v = 0.0
    for _ in range(n):
        v = [v]
    return v


def _set(out, definition):
    root = zarr.open_group(str(out), mode="r+")
    root.attrs["avblocks_sweep"] = definition if isinstance(definition, str) else \
        json.dumps(definition)


def _refused(out, match, capsys=None, scenario=None):
    """Every way of opening or resuming ``out`` is refused (or, for opening,
    reads only data); nothing runs. ``scenario``: the Python file the
    person resuming names."""
    with pytest.raises(SweepError, match=match):
        av.sweep.resume(str(out), summary=False, plot=False, workers=1, scenario=scenario)
    if capsys is not None:
        from avblocks.cli import main
        named = [str(scenario)] if scenario is not None else []
        assert main(["sweep", *named, "--resume", str(out), "--quiet", "--no-plot",
                     "--workers", "1"]) == 2
        err = capsys.readouterr().err
        assert err.startswith("avblocks: error: ") and "Traceback" not in err


def test_new_stores_keep_no_python_text(tmp_path):
    out, d = _store(tmp_path)
    text = Path(SCEN).read_bytes()
    assert d["version"] == 2
    assert d["scenario"] == {"name": "goal_scenario", "kind": "py",
                             "path": str(Path(SCEN).resolve()),
                             "sha256": hashlib.sha256(text).hexdigest()}
    assert "make_diagram" not in (out / "zarr.json").read_text()


def test_a_stored_python_text_never_runs(tmp_path, capsys):
    """A definition as avblocks <= 0.3 wrote it (version 1, the .py text
    inside) whose text writes a marker: the file it names does not exist,
    or exists with other content; resume refuses, naming the file."""
    marker = tmp_path / "pwned.txt"
    out, d = _store(tmp_path)
    evil = MARKER_CODE.format(marker=str(marker))
    d["version"] = 1
    d["scenario"] = {"name": "goal", "kind": "py", "path": str(tmp_path / "gone.py"),
                     "text": evil}
    _set(out, d)
    _refused(out, "gone.py", capsys)
    _refused(out, "gone.py", capsys, scenario=tmp_path / "gone.py")
    (tmp_path / "gone.py").write_text("# another file\n")
    _refused(out, r"gone.py' changed since the sweep started: its SHA-256 is [0-9a-f]{64}, "
                  r"the store expects [0-9a-f]{64}", capsys, scenario=tmp_path / "gone.py")
    # the same attack in today's format: a text next to a path and a hash
    d["version"] = 2
    d["scenario"] = {"name": "goal", "kind": "py", "path": SCEN, "text": evil,
                     "sha256": hashlib.sha256(evil.encode()).hexdigest()}
    _set(out, d)
    _refused(out, "never chooses a Python file", capsys)
    _refused(out, "goal_scenario.py' changed since the sweep started", capsys, scenario=SCEN)
    study = Study.open(out)                       # reading it is fine: data only
    assert study.counts() == {"done": 1, "failed": 0, "missing": 1}
    study.to_xarray()
    assert not marker.exists()


def test_a_store_that_brings_its_own_python_file_never_runs_it(client, tmp_path, capsys):
    """A store can carry a Python file (inside itself, or next to it in a
    shared folder) and name it with its own SHA-256: the hash matches, yet
    resume never runs it unless the person resuming names that file; the
    file they name runs only with the stored hash, and the CLI takes it as
    the scenario argument (attack42: a store naming ``crafted.zarr/notes.py``
    ran it on `avblocks sweep --resume`)."""
    marker = tmp_path / "pwned.txt"
    out, d = _store(tmp_path)
    evil = MARKER_CODE.format(marker=str(marker)).encode()
    (out / "notes.py").write_bytes(evil)                 # inside the store
    (tmp_path / "beside.py").write_bytes(evil)           # next to it (a shared folder)
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        for path in ("crafted.zarr/notes.py", str(out / "notes.py"),
                     str(tmp_path / "beside.py")):
            d["scenario"] = {"name": "notes", "kind": "py", "path": path,
                             "sha256": hashlib.sha256(evil).hexdigest()}
            _set(out, d)
            _refused(out, "never chooses a Python file to run", capsys)
            # naming another file (the real scenario) does not run the store's
            _refused(out, "changed since the sweep started", capsys, scenario=SCEN)
            # nor does naming a scenario of another kind
            _refused(out, "is a sweep of py scenario", capsys, scenario="waypoints")
    finally:
        os.chdir(cwd)
    assert not marker.exists()
    # the sweep's own file, named: it runs (CLI: the scenario argument)
    scen = tmp_path / "goal_scenario.py"
    shutil.copy(SCEN, scen)
    (tmp_path / "mine").mkdir()
    out2, _ = _store(tmp_path / "mine", str(scen))
    from avblocks.cli import main
    assert main(["sweep", str(scen), "--resume", str(out2), "--scheduler",
                 client.scheduler.address, "--quiet", "--no-plot"]) == 0
    assert Study(out2).counts() == {"done": 2, "failed": 0, "missing": 0}


def test_a_changed_python_scenario_is_refused_and_the_same_one_runs(client, tmp_path):
    scen = tmp_path / "goal_scenario.py"
    shutil.copy(SCEN, scen)
    out, d = _store(tmp_path, str(scen))
    expected = hashlib.sha256(scen.read_bytes()).hexdigest()
    scen.write_text(scen.read_text() + "\nprint('changed')\n")
    got = hashlib.sha256(scen.read_bytes()).hexdigest()
    with pytest.raises(SweepError) as e:
        av.sweep.resume(str(out), scheduler=client, summary=False, plot=False,
                        scenario=str(scen))
    assert str(scen) in str(e.value) and expected in str(e.value) and got in str(e.value)
    shutil.copy(SCEN, scen)                              # the original content again
    study = av.sweep.resume(str(out), scheduler=client, summary=False, plot=False,
                            scenario=str(scen))
    assert study.counts() == {"done": 2, "failed": 0, "missing": 0}


def test_an_old_store_whose_file_is_unchanged_still_resumes(client, tmp_path):
    """Version 1 kept the text: when the file at its path still reads as
    that text, the file (not the stored text) runs."""
    scen = tmp_path / "goal_scenario.py"
    shutil.copy(SCEN, scen)
    out, d = _store(tmp_path, str(scen))
    d["version"] = 1
    d["scenario"] = {"name": "goal_scenario", "kind": "py", "path": str(scen),
                     "text": scen.read_text()}
    _set(out, d)
    study = av.sweep.resume(str(out), scheduler=client, summary=False, plot=False,
                            scenario=str(scen))
    assert study.counts()["done"] == 2


def test_a_builtin_name_that_is_a_path_is_refused(tmp_path, capsys):
    marker = tmp_path / "pwned.txt"
    evil = tmp_path / "evil.py"
    evil.write_text(MARKER_CODE.format(marker=str(marker)))
    out, d = _store(tmp_path)
    for name in (str(evil), "../evil.py", "evil.py", "loader", "formation.yaml"):
        d["scenario"] = {"name": name, "kind": "builtin"}
        _set(out, d)
        _refused(out, "no built-in scenario named")
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        d["scenario"] = {"name": "evil.py", "kind": "builtin"}
        _set(out, d)
        _refused(out, "no built-in scenario named", capsys)
    finally:
        os.chdir(cwd)
    assert not marker.exists()


@pytest.mark.parametrize("change,match", [
    (lambda d: d.update(version=99), "version 99.*upgrade avblocks"),
    (lambda d: d.update(version="2"), "version '2'"),
    (lambda d: d.update(scenario="formation"), "'scenario' must be a mapping"),
    (lambda d: d["scenario"].update(kind="exec"), "scenario.kind"),
    (lambda d: d["scenario"].update(sha256="abc"), "scenario.sha256"),
    (lambda d: d["scenario"].update(path="x\x00.py"), "scenario.path"),
    (lambda d: d["scenario"].update(path="a" * 5000), "scenario.path"),
    (lambda d: d["scenario"].update(path="../../../../etc/passwd"),
     "never chooses a Python file"),
    (lambda d: d.update(grid=[1, 2]), "grid must be a dict"),
    (lambda d: d.update(grid={"goal": []}), "has no values"),
    (lambda d: d.update(grid={"a": list(range(5000)), "b": list(range(5000))}),
     "25,000,000 cases, more than 10,000,000"),
    (lambda d: d.update(seeds="abc"), "seeds must be"),
    (lambda d: d.update(seeds=[True]), "seeds must be"),
    (lambda d: d.update(seeds=10**8), "seeds must be"),
    (lambda d: d.update(fixed=[1]), "'fixed' must be a mapping"),
    (lambda d: d.update(metrics={}), "'metrics' must be a list"),
    (lambda d: d.update(metrics=["a/b"]), "without '/'"),
    (lambda d: d.update(metric_refs={"min_gap": "os.system"}), "metric_refs.min_gap"),
    (lambda d: d.update(metric_refs={"min_gap": "os:system"}), "may not import"),
    (lambda d: d.update(metric_refs={"min_gap": "builtins:exec"}), "may not import"),
    (lambda d: d.update(metric_refs={"min_gap": "avblocks:_private"}), "metric_refs"),
    (lambda d: d.update(metric_refs={"nope": None}), "does not have"),
    (lambda d: d.update(log=5), "'log' must be"),
    (lambda d: d.update(log_every=-1), "'log_every' must be"),
    (lambda d: d.update(ensemble="yes"), "'ensemble' must be"),
    (lambda d: d.update(token=5), "'token' must be"),
    (lambda d: d.update(grid={"goal": [_deep(150), 1.0]}), "nest deeper than 100"),
    (lambda d: d.update(fixed={"n": "x" * 200_000}), "more than 100,000"),
    (lambda d: d.update(fixed={"n": 10**150}), "digits"),
])
def test_junk_definitions_are_refused_by_entry(tmp_path, change, match):
    out, d = _store(tmp_path)
    change(d)
    _set(out, d)
    _refused(out, match)
    if "may not import" not in match and "never chooses" not in match:
        with pytest.raises(SweepError, match=match):
            Study.open(out)


@pytest.mark.parametrize("text,match", [
    ("[" * 100_000 + "]" * 100_000, "not valid JSON"),
    ('{"version": 2, "grid": ' + "[" * 500 + "]" * 500 + "}", "nest deeper"),
    ("not json", "not valid JSON"),
    ("[1, 2]", "not a mapping"),
    ('{"seeds": 1' + "0" * 5000 + "}", "not valid JSON"),
])
def test_unreadable_definitions_are_refused(tmp_path, text, match):
    out, _ = _store(tmp_path)
    _set(out, text)
    _refused(out, match)


def test_a_huge_definition_is_refused_before_it_is_read(tmp_path):
    out, d = _store(tmp_path)
    meta = json.loads((out / "zarr.json").read_text())
    meta["attributes"]["padding"] = "x" * (17 * 1024**2)
    (out / "zarr.json").write_text(json.dumps(meta))
    _refused(out, "root metadata is 17.8 MB")


def test_a_case_padded_with_huge_metadata_is_refused_before_it_is_parsed(tmp_path):
    """Case records are a few kB; two padded to 164 MB each made opening the
    store take 1.9 GB and 42 s (attack42). A case's metadata file over the
    definition's own limit is refused, by size, before zarr parses it."""
    out, d = _store(tmp_path, cases=(0, 1))
    meta = out / "cases" / "c0000001" / "zarr.json"
    j = json.loads(meta.read_text())
    j["attributes"]["error"] = "x" * (17 * 1024**2)
    meta.write_text(json.dumps(j))
    with pytest.raises(SweepError, match="case 'c0000001' of the store has 17.8 MB of "
                                         "metadata"):
        Study(out).counts()
    _refused(out, "17.8 MB of metadata")


def test_crafted_case_groups_and_arrays_are_read_as_data_or_refused(tmp_path):
    out, d = _store(tmp_path, cases=(0, 1))
    cases = zarr.open_group(str(out / "cases"), mode="r+", zarr_format=3)
    for name in ("cabc", "c0000001x", "c999999999", "x0000000"):
        g = cases.create_group(name)
        g.attrs.update({"status": "done"})
    cases["c0000000"].attrs.update({"status": "hacked", "error": 5})
    recs = Study(out).records()
    assert sorted(recs) == [0, 1]                        # only canonical, in range
    assert recs[0]["status"] == "failed" and "unknown status" in recs[0]["error"]
    g = cases["c0000001"]["metrics"]
    g.create_array("text", data=np.array(["a", "b"]))
    with pytest.raises(SweepError, match="holds <U1, not numbers"):
        Study(out).to_xarray()
    del g["text"]
    g.create_array("huge", shape=(10**7,), dtype="float64", chunks=(10**7,))
    with pytest.raises(SweepError, match="10,000,000 values, more than 10,000"):
        Study(out).to_xarray()


def test_metric_references_import_only_from_named_modules(tmp_path):
    from avblocks.sweep.spec import resolve_metric
    with pytest.raises(SweepError, match="may not import.*--metrics-module statistics"):
        resolve_metric("statistics:mean", "m")
    import statistics
    assert resolve_metric("statistics:mean", "m", ["statistics"]) is statistics.mean
    with pytest.raises(SweepError, match="not a Python function"):
        resolve_metric("avblocks.sweep.store:MAX_CASES", "m")
    with pytest.raises(SweepError, match="not 'package.module:function'"):
        resolve_metric("avblocks.sweep:_finish", "m")
    # a function another module imported, or reached through another module
    # (attack42: shutil.rmtree and subprocess.getoutput were metrics)
    for ref, home in (("avblocks.core.confined:shutil.rmtree", "'shutil'"),
                      ("avblocks.viz.diagram:subprocess.getoutput", "'subprocess'"),
                      ("avblocks.core.confined:os.path.join", "'os'"),
                      ("avblocks.analysis.model:dataclass", "'dataclasses'")):
        with pytest.raises(SweepError, match=home):
            resolve_metric(ref, "m")
    assert resolve_metric("avblocks.sweep.metrics:min_gap", "m") is av.sweep.METRICS["min_gap"]
