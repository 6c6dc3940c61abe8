"""Sweeps on a real Dask LocalCluster (2 worker processes on 127.0.0.1).

The cases are tiny (3 single integrators, 20-100 RK4 steps) so the module
stays well under a minute; the truth is the closed-form solution
``x(t) = g + (x0 - g) exp(-k t)`` and the same cases run one by one through
``avblocks run``'s loader and ``simulate`` in this process.
"""

from __future__ import annotations

import os
import shutil
import signal
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import avblocks as av

if not os.environ.get("CI"):
    pytest.importorskip("dask.distributed")
    pytest.importorskip("zarr")
from dask.distributed import Client, LocalCluster  # noqa: E402

from avblocks.cli import load_any  # noqa: E402
from avblocks.sweep import Study, SweepError  # noqa: E402
from avblocks.sweep.cli import parse_grid  # noqa: E402

pytestmark = pytest.mark.sweep

SCEN = str(Path(__file__).with_name("goal_scenario.py"))
GRID = {"ctl.k": [0.5, 1.0, 2.0], "goal": [0.0, 1.0, 2.0]}
SEEDS = 4
FIXED = {"n": 3, "t_final": 1.0}


def final_distance_fn():
    def final_distance(res):        # nested: shipped to workers by value
        p = res["fleet.position"]
        return float(np.sqrt(((p[-1] - p[-1].mean(0)) ** 2).sum(1)).mean())
    return final_distance


def metrics():
    return {"final_distance": final_distance_fn(), "min_gap": "min_gap",
            "final_x": lambda res: res["fleet.position"][-1, :, 0]}


def serial_case(k, goal, seed, **fixed):
    """One case the plain way: the scenario loader, simulate, the metric."""
    d, sim, *_ = load_any(SCEN, {**FIXED, **fixed, "goal": goal, "seed": seed})
    sim["seed"] = seed
    res = av.simulate(d, progress=False, params={"ctl.k": k}, **sim)
    return res


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


@pytest.fixture(scope="module")
def serial():
    """Metrics of every case of the 3x3x4 grid run one by one, here."""
    fd = final_distance_fn()
    out = {}
    for k in GRID["ctl.k"]:
        for g in GRID["goal"]:
            for s in range(SEEDS):
                res = serial_case(k, g, s)
                out[(k, g, s)] = (fd(res), av.sweep.METRICS["min_gap"](res),
                                  res["fleet.position"][-1, :, 0])
    return out


def assert_matches_serial(ds, serial):
    for (k, g, s), (fd, gap, fx) in serial.items():
        case = ds.sel({"ctl.k": k, "goal": g, "seed": s})
        assert str(case["status"].values) == "done"
        # bit-identical, not close: same seed, same code path
        assert case["final_distance"].values == fd
        assert case["min_gap"].values == gap
        np.testing.assert_array_equal(case["final_x"].values, fx)


def test_grid_sweep_matches_serial_runs_and_closed_form(client, serial, tmp_path):
    out = tmp_path / "s.zarr"
    study = av.sweep(SCEN, grid=GRID, seeds=SEEDS, metrics=metrics(), out=str(out),
                     fixed=FIXED, scheduler=client, summary=False)
    assert study.last_run["ran"] == 36 and study.last_run["done"] == 36
    ds = study.to_xarray()
    assert ds["final_distance"].dims == ("ctl.k", "goal", "seed")
    assert ds["final_x"].dims == ("ctl.k", "goal", "seed", "final_x_dim0")
    assert_matches_serial(ds, serial)
    # independent truth: x(1) = g + (x0 - g) exp(-k) (RK4, dt = 0.05)
    for k in GRID["ctl.k"]:
        for g in GRID["goal"]:
            for s in range(SEEDS):
                x0 = np.random.default_rng(s).uniform(-1.0, 1.0, (3, 2))
                truth = g + (x0[:, 0] - g) * np.exp(-k)
                got = ds["final_x"].sel({"ctl.k": k, "goal": g, "seed": s}).values
                np.testing.assert_allclose(got, truth, atol=1e-5)
    # a plot per scalar metric next to the store (heatmap: 2 grid dims)
    pngs = sorted(p.name for p in tmp_path.glob("s_*.png"))
    assert pngs == ["s_final_distance.png", "s_min_gap.png"]
    from matplotlib.image import imread
    img = imread(tmp_path / "s_final_distance.png")
    assert img.shape[0] > 300 and img[..., :3].std() > 0.05     # not blank
    # the summary names every grid point
    text = study.summary()
    assert text.count("\n") >= 9 + 2 and "36 cases: 36 done, 0 failed, 0 missing" in text
    # resume: drop five cases and one half-written one; only those six run again
    before = study.records()
    gone = [0, 7, 13, 22, 35]
    for cid in gone:
        shutil.rmtree(out / "cases" / f"c{cid:07d}")
    half = out / "cases" / "c0000030" / "zarr.json"
    half.write_text(half.read_text().replace('"status"', '"status_"'))
    assert Study(out).counts() == {"done": 30, "failed": 0, "missing": 6}
    with pytest.raises(SweepError, match="cannot be imported by name"):
        av.sweep.resume(str(out), scheduler=client, summary=False, plot=False,
                        scenario=SCEN)
    fns = {k: v for k, v in metrics().items() if callable(v)}   # not importable by name
    again = av.sweep.resume(str(out), scheduler=client, summary=False, plot=False,
                            metrics=fns, scenario=SCEN)
    assert again.last_run["ran"] == 6 and again.last_run["done"] == 6
    after = again.records()
    for cid, rec in before.items():
        if cid not in gone and cid != 30:
            assert after[cid]["finished"] == rec["finished"]
            assert after[cid]["worker"] == rec["worker"]
    assert_matches_serial(again.to_xarray(), serial)
    # the CLI resumes through a running scheduler, with nothing left to do
    from avblocks.cli import main
    addr = client.scheduler.address
    assert main(["sweep", "--resume", str(out), "--scheduler", addr, "--quiet",
                 "--no-plot"]) == 0
    # and refuses to overwrite by accident
    with pytest.raises(SweepError, match="already exists"):
        av.sweep(SCEN, grid=GRID, seeds=SEEDS, metrics=metrics(), out=str(out),
                 fixed=FIXED, scheduler=client)


def test_killed_worker_does_not_lose_the_sweep(client, serial, tmp_path):
    out = tmp_path / "k.zarr"
    pids = client.run(os.getpid)
    victim = sorted(pids.values())[0]
    killed = {}

    def killer():
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            done = sum('"status"' in p.read_text() for p in
                       (out / "cases").glob("c*/zarr.json")) if (out / "cases").exists() else 0
            if done >= 4:
                os.kill(victim, signal.SIGKILL)
                killed["at"] = done
                return
            time.sleep(0.02)

    th = threading.Thread(target=killer, daemon=True)
    th.start()
    study = av.sweep(SCEN, grid=GRID, seeds=SEEDS, metrics=metrics(), out=str(out),
                     fixed={**FIXED, "t_final": 3.0, "dt": 0.05}, scheduler=client,
                     summary=False, plot=False)
    th.join()
    assert "at" in killed and killed["at"] < 36, "the worker was not killed mid-sweep"
    assert study.counts() == {"done": 36, "failed": 0, "missing": 0}
    # the killed process did no more work; another finished its cases
    workers = {r["worker"].rsplit(":", 1)[1] for r in study.records().values()}
    assert len(workers) >= 2
    ds = study.to_xarray()
    for (k, g, s) in list(serial)[:6]:
        res = serial_case(k, g, s, t_final=3.0)
        assert ds["final_distance"].sel({"ctl.k": k, "goal": g, "seed": s}).values == \
            final_distance_fn()(res)
    client.wait_for_workers(2, timeout=60)      # the nanny restarted it


def test_failing_case_is_recorded_and_the_sweep_goes_on(client, tmp_path):
    out = tmp_path / "f.zarr"

    def picky(res):
        if res["fleet.position"].shape[1] == 2:
            raise RuntimeError("two agents are not enough")
        return 1.0

    study = av.sweep(SCEN, grid={"goal": [0.0, 1.0], "n": [2, 3]}, seeds=2,
                     metrics={"picky": picky}, out=str(out),
                     fixed={"refuse_goal": 1.0, "t_final": 0.2}, scheduler=client,
                     summary=False)
    ds = study.to_xarray()
    st = ds["status"]
    assert (st.sel(goal=1.0) == "failed").all()                # make_diagram raised
    assert (st.sel(goal=0.0, n=2) == "failed").all()           # the metric raised
    assert (st.sel(goal=0.0, n=3) == "done").all()
    assert ds["picky"].sel(goal=0.0, n=3).values.tolist() == [1.0, 1.0]
    assert np.isnan(ds["picky"].sel(goal=0.0, n=2)).all()
    errs = study.errors()
    assert len(errs) == 6
    assert "goal 1.0 refused on purpose" in errs["goal=1.0, n=3, seed=1"]
    assert errs["goal=0.0, n=2, seed=0"].startswith(
        "RuntimeError: two agents are not enough")
    assert study.counts() == {"done": 2, "failed": 6, "missing": 0}
    # resume leaves failed cases alone unless asked
    assert av.sweep.resume(str(out), scheduler=client, summary=False,
                           plot=False).last_run["ran"] == 0


def test_default_local_cluster_is_on_loopback_and_closed():
    from avblocks.sweep.runner import client_for
    with client_for(workers=2) as c:
        info = c.scheduler_info()
        addrs = [c.scheduler.address] + list(info["workers"])
        addrs += [w["nanny"] for w in info["workers"].values()]
        assert len(info["workers"]) == 2
        assert all(a.startswith("tcp://127.0.0.1:") for a in addrs), addrs
        assert all(w["nthreads"] == 1 for w in info["workers"].values())
        # the scheduler's HTTP server: loopback, a free port, no dashboard pages
        import urllib.error
        import urllib.request
        port = info["services"]["dashboard"]
        assert port != 8787
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/health") as r:
            assert r.status == 200
        with pytest.raises(urllib.error.HTTPError, match="404"):
            urllib.request.urlopen(f"http://127.0.0.1:{port}/status")
        pids = list(c.run(os.getpid).values())
    time.sleep(0.5)
    for pid in pids:          # the worker processes are gone
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)


def test_cli_sweeps_a_builtin_scenario(client, tmp_path, capsys):
    from avblocks.cli import main
    out = tmp_path / "form.zarr"
    rc = main(["sweep", "formation", "--grid", "gain=0.5,1.5", "--set", "agents=2",
               "--set", "t_final=3", "--seeds", "2", "--out", str(out),
               "--scheduler", client.scheduler.address,
               "--metric", "final_error", "--log", "fleet.pose", "--log-every", "5",
               "--quiet"])
    assert rc == 0
    printed = capsys.readouterr().out
    assert "4 cases: 4 done, 0 failed, 0 missing" in printed
    study = av.sweep.open(str(out))
    ds = study.to_xarray(logs=True)
    assert ds["final_error"].dims == ("gain", "seed")
    assert ds["log.fleet.pose"].shape == (2, 2, 31 // 5 + 1, 2, 3)
    # the stored metric equals the one of the case run alone
    d, sim, *_ = load_any("formation", {"agents": 2, "t_final": 3, "gain": 1.5,
                                          "seed": 1})
    res = av.simulate(d, progress=False, **{**sim, "seed": 1})
    assert ds["final_error"].sel(gain=1.5, seed=1).values == \
        av.sweep.METRICS["final_error"](res)
    np.testing.assert_array_equal(ds["log.fleet.pose"].sel(gain=1.5, seed=1).values,
                                  res["fleet.pose"][::5])
    assert (tmp_path / "form_final_error.png").exists()


# ------------------------------------------------------------ no cluster
def test_grid_parsing_and_case_numbering():
    assert parse_grid(["k=0.5,1,2", "name=a,b", "x=0:1:3"]) == \
        {"k": [0.5, 1, 2], "name": ["a", "b"], "x": [0.0, 0.5, 1.0]}
    with pytest.raises(SweepError, match="name=v1"):
        parse_grid(["k"])
    # a count that NumPy refuses or that would not fit: one clean error
    # (attack42: ValueError and MemoryError tracebacks before)
    for bad in ("k=1:2:-5", "k=1:2:0", "k=1:2:100000000", "k=nan:1:3", "k=1:inf:3"):
        with pytest.raises(SweepError, match="a count from 1 to 10,000,000"):
            parse_grid([bad])
    with pytest.raises(SweepError, match="25,000,000 cases, more than 10,000,000"):
        av.sweep.make_spec(SCEN, {"a": list(range(5000)), "b": list(range(5000))})
    spec, _ = av.sweep.make_spec(SCEN, {"a": [1, 2, 3], "b": ["x", "y"]}, seeds=[5, 6])
    assert spec.shape == (3, 2, 2) and spec.n_cases == 12
    # row-major over (a, b, seed): case 7 = a index 1, b index 1, seed index 1
    assert spec.case(7) == ({"a": 2, "b": "y"}, 6)


def test_bad_sweeps_are_refused_before_any_task(tmp_path):
    with pytest.raises(SweepError, match="unknown built-in metric 'final_eror'"):
        av.sweep.make_spec("formation", {"gain": [1]}, metrics=["final_eror"])
    with pytest.raises(SweepError, match="no built-in scenario or file"):
        av.sweep.make_spec("formaton")
    with pytest.raises(SweepError, match="both in grid and fixed"):
        av.sweep.make_spec("formation", {"gain": [1]}, fixed={"gain": 2})
    with pytest.raises(SweepError, match="seeds must be"):
        av.sweep.make_spec("formation", seeds=0)
    with pytest.raises(SweepError, match="unknown parameter"):
        av.sweep("formation", grid={"gian": [1, 2]}, out=str(tmp_path / "x.zarr"))
    with pytest.raises(SweepError, match="no such numeric parameter"):
        av.sweep(SCEN, grid={"ctl.kk": [1, 2]}, out=str(tmp_path / "y.zarr"))
    assert not (tmp_path / "x.zarr").exists() and not (tmp_path / "y.zarr").exists()
    with pytest.raises(SweepError, match="no sweep store"):
        av.sweep.resume(str(tmp_path / "nothing.zarr"))


def test_builtin_metrics_against_direct_computation():
    from scipy.spatial.distance import pdist
    rng = np.random.default_rng(0)
    t = np.linspace(0, 2, 5)
    pose = rng.uniform(0, 5, (5, 4, 3))
    done = np.array([[0, 0, 0, 0], [1, 0, 0, 0], [1, 1, 1, 1], [1, 1, 1, 1],
                     [1, 1, 0, 1]], bool)
    err = rng.normal(size=(5, 4, 2))
    res = av.Results(t, {"fleet.pose": pose, "drive.done": done, "lf.error": err})
    M = av.sweep.METRICS
    assert M["min_gap"](res) == pytest.approx(min(pdist(p[:, :2]).min() for p in pose))
    assert M["done_fraction"](res) == 0.75
    assert M["time_to_done"](res) == t[2]
    assert M["final_error"](res) == pytest.approx(np.sqrt((err[-1] ** 2).sum(1).mean()))
    steps = np.linalg.norm(np.diff(pose[:, :, :2], axis=0), axis=2)
    assert M["path_length"](res) == pytest.approx(steps.sum(0).mean())
    with pytest.raises(av.sweep.MetricError, match="needs a logged signal named"):
        M["final_order"](res)


@pytest.mark.slow          # JAX compiles in each worker process
def test_ensemble_sweep_matches_numpy_runs(client, serial, tmp_path):
    if not os.environ.get("CI"):
        pytest.importorskip("jax")
    out = tmp_path / "e.zarr"
    grid = {"ctl.k": [0.5, 2.0], "goal": [1.0]}
    study = av.sweep(SCEN, grid=grid, seeds=SEEDS, metrics=metrics(), out=str(out),
                     fixed=FIXED, scheduler=client, ensemble=True, summary=False,
                     plot=False)
    assert study.counts() == {"done": 8, "failed": 0, "missing": 0}
    recs = study.records()
    assert {r["ensemble"] for r in recs.values()} == {SEEDS}     # one task per grid point
    ds = study.to_xarray()
    for k in grid["ctl.k"]:
        for s in range(SEEDS):
            fd, gap, fx = serial[(k, 1.0, s)]
            case = ds.sel({"ctl.k": k, "goal": 1.0, "seed": s})
            np.testing.assert_allclose(case["final_x"].values, fx, rtol=0, atol=1e-12)
            assert abs(float(case["final_distance"]) - fd) < 1e-12
    # a scenario JAX cannot trace is refused before any task
    with pytest.raises(SweepError, match="traceable"):
        av.sweep(SCEN, grid={"goal": [1.0]}, fixed={**FIXED, "untraceable": True},
                 out=str(tmp_path / "no.zarr"), scheduler=client, ensemble=True)


def test_progress_is_silent_off_a_terminal(capsys):
    from avblocks.sweep.runner import _Progress
    bar = _Progress(5, None)              # pytest's stderr is not a terminal
    for s in ("done", "failed", "done"):
        bar.update(s)
    bar.close()
    assert bar.bar is None and (bar.done, bar.failed) == (2, 1)
    assert capsys.readouterr().err == ""


def _evil_blob(marker):
    """A pickle that writes ``marker`` when it is loaded."""
    import base64
    import pickle

    class Evil:
        def __reduce__(self):
            return (Path(marker).write_text, ("pwned",))
    return base64.b64encode(pickle.dumps({"evil": Evil()})).decode()


def test_a_store_never_runs_the_code_it_holds(client, tmp_path):
    """A store with a pickled metric that would write a file when loaded
    (as avblocks 0.1.0 wrote them): resume, Study.open, to_xarray and the CLI
    leave no file and say what is missing; importable metrics come back by
    name, and new stores hold references, never code."""
    import json

    import zarr
    gap = av.sweep.METRICS["min_gap"]
    out = tmp_path / "t.zarr"
    av.sweep(SCEN, grid={"goal": [0.0, 1.0]}, seeds=2, fixed=FIXED, out=str(out),
             metrics={"gap": gap, "final_x": lambda r: r["fleet.position"][-1, :, 0]},
             scheduler=client, summary=False, plot=False)
    root = zarr.open_group(str(out), mode="r+")
    spec = json.loads(root.attrs["avblocks_sweep"])
    assert spec["metric_refs"] == {"gap": "avblocks.sweep.metrics:min_gap", "final_x": None}
    assert "metrics_pickle" not in root.attrs and "_callables" not in spec
    # now make it hostile: a pickled metric, two cases gone
    marker = tmp_path / "pwned.txt"
    spec["metrics"].append("evil")
    root.attrs["avblocks_sweep"] = json.dumps(spec)
    root.attrs["metrics_pickle"] = _evil_blob(marker)
    for cid in (1, 3):
        shutil.rmtree(out / "cases" / f"c{cid:07d}")
    with pytest.raises(SweepError, match="'final_x'|'evil'"):
        av.sweep.resume(str(out), scheduler=client, summary=False, plot=False,
                        scenario=SCEN)
    with pytest.raises(SweepError, match="'evil'.*cannot be imported by name"):
        av.sweep.resume(str(out), scheduler=client, summary=False, plot=False,
                        metrics={"final_x": lambda r: r["fleet.position"][-1, :, 0]},
                        scenario=SCEN)
    study = Study.open(out)
    ds = study.to_xarray()
    assert ds["gap"].shape == (2, 2) and study.counts()["missing"] == 2
    from avblocks.cli import main
    assert main(["sweep", SCEN, "--resume", str(out), "--scheduler",
                 client.scheduler.address, "--quiet", "--no-plot"]) == 2
    assert not marker.exists()
    # importable metrics resume by name
    with pytest.raises(SweepError, match="no.such.module"):
        av.sweep.spec.resolve_metric("no.such.module:fn", "x")
    assert av.sweep.spec.resolve_metric("avblocks.sweep.metrics:min_gap", "gap") is gap


def test_plain_xarray_opens_a_finished_store(client, tmp_path):
    """`xarray.open_zarr(STORE)` in a process that never imports avblocks
    gives the whole sweep: grid names and seed as dimensions with their
    values, every metric, the status of every case."""
    import json
    import subprocess
    import sys
    out = tmp_path / "x.zarr"
    study = av.sweep(SCEN, grid={"ctl.k": [0.5, 2.0], "goal": [0.0, 1.0, 2.0]}, seeds=2,
                     fixed=FIXED, out=str(out), metrics=["min_gap"],
                     scheduler=client, summary=False, plot=False)
    code = ("import json, sys, xarray as xr\n"
            f"ds = xr.open_zarr({str(out)!r})\n"
            "print(json.dumps({'dims': dict(ds.sizes), 'k': ds['ctl.k'].values.tolist(),"
            " 'seed': ds['seed'].values.tolist(), 'gap': ds['min_gap'].values.tolist(),"
            " 'status': ds['status'].values.tolist(),"
            " 'avblocks': any(m.startswith('avblocks') for m in sys.modules)}))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=120, check=True)
    got = json.loads(r.stdout)
    assert got["avblocks"] is False
    assert got["dims"] == {"ctl.k": 2, "goal": 3, "seed": 2}
    assert got["k"] == [0.5, 2.0] and got["seed"] == [0, 1]
    ref = study.to_xarray()
    np.testing.assert_array_equal(np.asarray(got["gap"]), ref["min_gap"].values)
    assert np.all(np.asarray(got["status"]) == "done")
