"""Parameter sweeps and Monte Carlo studies on Dask (extra ``[sweep]``).

``av.sweep(scenario, grid=..., seeds=..., metrics=..., out=...)`` runs one
case per grid point and seed on a ``dask.distributed`` cluster (by default
a LocalCluster of one single-threaded worker process per core on
127.0.0.1, started and closed here); each worker writes its case straight
into one Zarr store, the client only counts. ``scheduler="tcp://host:8786"``
(or a ``Client``) sends the same cases to a running cluster.

The module itself is callable: ``avblocks.sweep(...)`` is
:func:`run_sweep`. See docs/sweeps.md.
"""

from __future__ import annotations

import hashlib
import json
import sys
import types
import uuid
from collections.abc import Callable

from .metrics import DEFAULTS, FALLBACK, METRICS, MetricError
from .spec import (
    SPEC_VERSION,
    Spec,
    SweepError,
    build_case,
    metric_reference,
    normalise_grid,
    normalise_seeds,
    scenario_source,
    split_overrides,
)
from .study import Study


def _metrics_spec(metrics, scenario_name):
    """``(names, {name: callable})`` from None, names or a dict."""
    if metrics is None:
        names = list(DEFAULTS.get(scenario_name, FALLBACK))
        return names, {}
    if isinstance(metrics, str):
        metrics = [metrics]
    if isinstance(metrics, list | tuple):
        metrics = {m: m for m in metrics}
    if not isinstance(metrics, dict) or not metrics:
        raise SweepError("metrics must be metric names or a dict {name: fn(results)}",
                         found=repr(metrics))
    names, custom = [], {}
    for name, fn in metrics.items():
        if not isinstance(name, str) or not name or "/" in name:
            raise SweepError(f"metric names are non-empty strings without '/', "
                             f"found {name!r}")
        if isinstance(fn, str):
            if fn not in METRICS:
                raise SweepError(f"unknown built-in metric '{fn}'",
                                 hint=f"built-in metrics: {sorted(METRICS)}; or pass "
                                      "a callable fn(results) -> number")
            if fn != name:
                custom[name] = METRICS[fn]
        elif isinstance(fn, Callable):
            custom[name] = fn
        else:
            raise SweepError(f"metric '{name}' must be a built-in name or a callable",
                             found=type(fn).__name__)
        names.append(name)
    return names, custom


def _check_first_case(spec: Spec, case_id=0):
    """Build case ``case_id`` on the client so misspelt names (or a store's
    scenario that cannot be built here) fail before any task."""
    from ..core.errors import AvError
    try:
        d, sim = spec.build(case_id)
        params = sim.get("params") or {}
        compiled = d.build()
        for path in params:
            compiled.param_index(path)
        if spec.data.get("ensemble"):
            from .ensemble import check_traceable
            check_traceable(d)
    except SweepError:
        raise
    except AvError as e:
        raise SweepError(f"the first case ({spec.label(case_id)}) cannot be built: {e}") \
            from None


def make_spec(scenario, grid=None, seeds=1, metrics=None, *, fixed=None, log=None,
              log_every=1, ensemble=False) -> tuple[Spec, dict]:
    """The :class:`Spec` of a sweep and its custom metric callables."""
    src = scenario_source(scenario)
    g = normalise_grid(grid)
    fx = normalise_grid({k: [v] for k, v in (fixed or {}).items()})
    fx = {k: v[0] for k, v in fx.items()}
    clash = set(g) & set(fx)
    if clash:
        raise SweepError(f"{sorted(clash)} are both in grid and fixed")
    from .store import MAX_CASES
    n_cases = len(normalise_seeds(seeds))
    for v in g.values():
        n_cases *= len(v)
    if n_cases > MAX_CASES:
        raise SweepError(f"the grid and seeds make {n_cases:,} cases, more than "
                         f"{MAX_CASES:,}", hint="split the sweep into several stores")
    names, custom = _metrics_spec(metrics, src["name"])
    if log is True:
        log = ["*"]
    elif isinstance(log, str):
        log = [log]
    elif log is not None:
        log = [p if isinstance(p, str) else p.path for p in log]
        if not log:
            log = None
    if int(log_every) < 1:
        raise SweepError("log_every must be >= 1", found=log_every)
    data = {"version": SPEC_VERSION, "scenario": src, "grid": g,
            "seeds": normalise_seeds(seeds), "fixed": fx, "metrics": names,
            "log": log, "log_every": int(log_every), "ensemble": bool(ensemble)}
    data["metric_refs"] = {n: metric_reference(fn) for n, fn in custom.items()}
    from .store import stored_definition
    data["token"] = hashlib.sha1(json.dumps(stored_definition(data), sort_keys=True)
                                 .encode()).hexdigest()[:12]
    data["_callables"] = dict(custom)          # this process's functions, never stored
    data["_run"] = uuid.uuid4().hex            # a worker's cached spec is this run's
    return Spec(data), custom


def _scenario_key(src):
    """What makes two stored scenarios the same: a built-in's name, a
    file's kind and content hash."""
    src = src or {}
    if src.get("kind") == "builtin":
        return ("builtin", src.get("name"))
    return (src.get("kind"), src.get("sha256"))


def _same_cases(a: dict, b: dict):
    keys = ("grid", "seeds", "fixed", "metrics", "log", "log_every", "ensemble")
    diff = [k for k in keys if json.dumps(a.get(k), sort_keys=True) !=
            json.dumps(b.get(k), sort_keys=True)]
    if _scenario_key(a.get("scenario")) != _scenario_key(b.get("scenario")):
        diff.insert(0, "scenario")
    return diff


def run_sweep(scenario, grid=None, seeds=1, metrics=None, out="sweep.zarr", *,
              fixed=None, scheduler=None, workers=None, log=None, log_every=1,
              resume=False, overwrite=False, progress=None, plot=True, summary=True,
              dashboard=False, ensemble=False) -> Study:
    """Run ``scenario`` over ``grid`` x ``seeds`` on Dask; results in ``out``.

    Parameters
    ----------
    scenario : str
        Built-in scenario name (``avblocks list``) or a ``.yaml``/``.toml``/
        ``.py`` scenario file (its text is stored with the sweep).
    grid : dict, optional
        ``{name: [values]}``. A name is a scenario parameter (``agents``),
        a simulation setting (``simulation.t_final``) or a numeric block
        parameter (``drive.gain``), exactly as ``avblocks run --set`` names them.
    seeds : int or list of int
        ``20`` means seeds 0..19. Each case's seed goes to the scenario's
        ``seed`` parameter (when it has one) and to ``simulate(seed=)``.
    metrics : None, list of str or dict
        Built-in metric names (:data:`METRICS`) and/or ``{name: fn}`` with
        ``fn(results) -> number or small array``. Default: the built-in
        scenario's usual metrics (:data:`DEFAULTS`).
    out : str
        The Zarr store (a folder, or a URL zarr opens). It must be reachable
        by every worker (a shared filesystem or an object store on a cluster).
    fixed : dict, optional
        Overrides applied to every case (``{"agents": 3}``).
    scheduler : None, str or dask.distributed.Client
        None: a LocalCluster of ``workers`` processes (default one per core)
        on 127.0.0.1, closed at the end. A ``"tcp://host:8786"`` address or a
        Client: that cluster.
    workers : int, optional
        Worker processes of the local cluster.
    log : None, True or list of str
        Also store these logged ports per case (True: everything the
        scenario logs), decimated by ``log_every``.
    resume : bool
        ``out`` exists: run only its missing cases (the sweep definition
        must be the same).
    overwrite : bool
        Replace an existing store.
    progress : bool, optional
        Progress bar (default: only on a terminal, not in CI).
    plot, summary : bool
        Write the metric plots next to the store; print the summary table.
    dashboard : bool
        Serve the Dask dashboard of the local cluster on 127.0.0.1 (a free
        port; ``client.dashboard_link``).
    ensemble : bool
        One task per grid point runs all its seeds as one vmapped JAX
        ensemble (``avblocks.compile(...).ensemble``) instead of one NumPy
        run per case. Needs a traceable diagram (extra ``[jax]``); metrics
        then agree with the NumPy runs to round-off. See docs/sweeps.md for
        when it pays.

    Returns
    -------
    Study
    """
    from . import store
    from .runner import client_for, execute
    spec, _custom = make_spec(scenario, grid, seeds, metrics, fixed=fixed, log=log,
                              log_every=log_every, ensemble=ensemble)
    exists = store.store_exists(out)
    if exists and resume:
        root = store.open_store(out)
        old, _blob = store.read_spec(root)
        diff = _same_cases(old, spec.data)
        if diff:
            raise SweepError(f"'{out}' holds a different sweep (differs in {diff})",
                             hint="resume with the same arguments, or "
                                  "avblocks.sweep.resume(out) to use the stored ones")
        return resume_sweep(out, scheduler=scheduler, workers=workers, progress=progress,
                            plot=plot, summary=summary, dashboard=dashboard,
                            metrics=_custom or None, modules=_metric_modules(_custom),
                            scenario=scenario)
    if exists and not overwrite:
        raise SweepError(f"'{out}' already exists",
                         hint="pass resume=True to finish it, overwrite=True to "
                              "replace it, or another out=")
    _check_first_case(spec)
    store.create_store(out, spec.data, overwrite=overwrite)       # stored: no "_" keys
    with client_for(scheduler, workers, dashboard) as client:
        counts = execute(spec, range(spec.n_cases), out, client, progress)
    return _finish(out, counts, plot, summary)


def _metric_modules(custom):
    """The modules of the metric functions handed to this call."""
    return tuple(sorted({getattr(fn, "__module__", "") for fn in (custom or {}).values()
                         if getattr(fn, "__module__", "")}))


def resume_sweep(out, *, scheduler=None, workers=None, retry_failed=False, progress=None,
                 plot=True, summary=True, dashboard=False, metrics=None,
                 modules=(), scenario=None) -> Study:
    """Run the cases of the sweep stored at ``out`` that are missing (and
    the failed ones with ``retry_failed=True``), with the stored definition.

    The store holds no code and nothing in it is executed, nor chosen to be
    executed. Its definition is checked entry by entry first
    (:func:`avblocks.sweep.store.check_definition`). A ``.py`` scenario is
    stored by path and SHA-256 only, and a store never picks a Python file
    to run (it could bring one along, inside itself or next to it in a
    shared folder): the person resuming names the file, ``scenario=``
    (CLI: ``avblocks sweep FILE.py --resume STORE``), and it runs only when
    it has the stored hash (the bytes checked are the bytes run); else a
    :class:`SweepError` names the stored file and the hashes. ``scenario``
    given for a built-in or YAML/TOML sweep must be that same scenario.
    Custom metrics come back by their stored reference
    (``"package.module:function"``), imported by name only from
    ``avblocks`` or one of ``modules`` (module names you trust, CLI
    ``--metrics-module``), or from ``metrics={name: fn}``."""
    from . import store
    from .runner import client_for, execute
    from .spec import checked_python
    root = store.open_store(out)
    data, _ = store.read_spec(root)
    if isinstance(modules, str):
        modules = (modules,)
    if not all(isinstance(m, str) and m for m in modules or ()):
        raise SweepError("resume's modules= is a list of module names",
                         found=repr(modules)[:80])
    data = {**data, "_run": uuid.uuid4().hex, "_modules": tuple(modules or ())}
    if metrics:
        if not isinstance(metrics, dict) or not all(callable(f) for f in metrics.values()):
            raise SweepError("resume's metrics= is a dict {name: fn(results)}",
                             found=type(metrics).__name__)
        unknown = sorted(set(metrics) - set(data["metrics"]))
        if unknown:
            raise SweepError(f"metrics {unknown} are not in this sweep",
                             hint=f"its metrics: {data['metrics']}")
        data["_callables"] = dict(metrics)
    spec = Spec(data)
    todo = Study(out).missing(retry_failed)
    src = data["scenario"]
    if scenario is not None:
        _same_scenario(scenario, src, out)
    if len(todo):
        metric_fns = spec.metric_fns()  # every metric found before any case runs
        if src["kind"] == "py":                    # the file you named, checked
            data["scenario"] = checked_python(_named_python(scenario, src, out))
        elif src["kind"] in ("yaml", "toml"):
            from .spec import _stored_folder
            data["scenario"] = {**src, "_folder": _stored_folder(src) or ""}
        spec = Spec(data)
        spec._metric_fns = metric_fns
        _check_first_case(spec, todo[0])
    with client_for(scheduler, workers, dashboard) as client:
        counts = execute(spec, todo, out, client, progress)
    return _finish(out, counts, plot, summary)


def _named_python(scenario, src, out) -> dict:
    """The stored ``.py`` scenario ``src`` read from the file the person
    resuming named (``scenario``), never from a path the store chose."""
    from pathlib import Path
    if scenario is None:
        path = src["path"]
        raise SweepError(f"this sweep runs the Python scenario '{path}' (SHA-256 "
                         f"{src['sha256']}); a store never chooses a Python file to run",
                         hint="if you ran this sweep, name your scenario file: avblocks "
                              f"sweep FILE.py --resume {out} (av.sweep.resume({str(out)!r}, "
                              "scenario=FILE.py)); a store someone sent you may name a file "
                              "it brought along: run only code you have read")
    return {**src, "path": str(Path(str(scenario)).resolve())}


def _same_scenario(scenario, src, out):
    """``scenario`` (named by the person resuming) is the stored one: the
    same built-in, or a file of the same kind (its hash is checked where the
    file is read)."""
    from pathlib import Path

    from ..scenarios import builtin_scenarios
    p = Path(str(scenario))
    kind = "builtin" if not p.is_file() and str(scenario) in builtin_scenarios() else \
        {".py": "py", ".yaml": "yaml", ".yml": "yaml", ".toml": "toml"}.get(p.suffix)
    same = kind == src["kind"] and (kind != "builtin" or str(scenario) == src["name"])
    if same and kind in ("yaml", "toml"):
        same = scenario_source(scenario)["sha256"] == src.get("sha256")
    if not same:
        stored = src["name"] if src["kind"] == "builtin" else src.get("path")
        raise SweepError(f"'{out}' is a sweep of {src['kind']} scenario '{stored}', not of "
                         f"'{str(scenario)[:200]}'",
                         hint="name the scenario the sweep ran, or leave it out for a "
                              "built-in or YAML scenario")


def _finish(out, counts, plot, summary) -> Study:
    study = Study(out, last_run=counts)
    study.write_dataset()
    if summary:
        print(study.summary())
        failed = study.errors()
        for label, err in list(failed.items())[:5]:
            print(f"failed: {label}: {err.splitlines()[0] if err else ''}")
    if plot:
        files = study.plot()
        if summary:
            for f in files:
                print(f"wrote {f}")
    return study


def open_study(out) -> Study:
    """Read a sweep's store (finished or not)."""
    return Study(out)


resume = resume_sweep
open = open_study  # noqa: A001 - avblocks.sweep.open(out), like xarray.open_dataset


class _CallableModule(types.ModuleType):
    def __call__(self, *args, **kwargs):
        return run_sweep(*args, **kwargs)


sys.modules[__name__].__class__ = _CallableModule

__all__ = ["run_sweep", "resume_sweep", "resume", "open_study", "Study", "Spec",
           "SweepError", "MetricError", "METRICS", "DEFAULTS", "make_spec", "build_case",
           "split_overrides"]
