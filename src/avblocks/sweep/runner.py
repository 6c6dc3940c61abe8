"""Run a sweep's cases on Dask; each worker writes its own case to the store.

The client keeps only a bounded window of futures in flight (a few per
worker thread) and gets back a few bytes per case (status, wall time), so
its memory does not grow with the number of cases or the size of the logs.
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import sys
import time
from itertools import islice

import numpy as np

from . import store
from .spec import Spec, SweepError
from .spec import cached_spec as _spec


def compute_case(spec: Spec, case_id: int):
    """Run one case; ``(metrics, logs)``. Raises what the case raises.

    This is the whole computation of a case, the same whether it runs
    alone, on a worker or in a resumed sweep: same seed, same overrides,
    same code, hence bit-identical metrics.
    """
    from ..core.frontend import simulate
    d, sim = spec.build(case_id)
    sim.setdefault("t_final", 10.0)
    want = spec.data.get("log")
    if want:
        logged = sim.get("log")
        names = [p if isinstance(p, str) else p.path for p in (logged or [])]
        if logged is not None:
            sim["log"] = list(logged) + [p for p in want if p not in names]
    res = simulate(d, progress=False, **sim)
    metrics = {}
    for name, fn in spec.metric_fns().items():
        v = np.asarray(fn(res))
        if v.dtype == object or v.size > 10_000:
            raise SweepError(f"metric '{name}' returned {v.dtype} of shape {v.shape}",
                             hint="a metric returns a number or a small numeric array")
        metrics[name] = v
    logs = None
    if want:
        every = int(spec.data.get("log_every") or 1)
        keys = list(res.keys()) if want is True or want == ["*"] else want
        logs = {"time": res.t[::every]}
        for k in keys:
            logs[k if isinstance(k, str) else k.path] = res[k][::every]
    return metrics, logs


def run_case(spec_data: dict, case_id: int, out: str) -> dict:
    """The Dask task: run case ``case_id``, write its group, return its
    record (a few bytes). A case that raises is recorded as failed."""
    spec = _spec(spec_data)
    values, seed = spec.case(case_id)
    t0 = time.perf_counter()
    metrics = logs = None
    try:
        metrics, logs = compute_case(spec, case_id)
        status, error = "done", ""
    except Exception as e:  # noqa: BLE001 - every failure of a case is recorded
        status, error = "failed", store.failure_text(e)
    rec = {"status": status, "error": error, "wall_s": time.perf_counter() - t0,
           "seed": int(seed), "values": {k: values[k] for k in spec.grid}}
    store.write_case(out, case_id, rec, metrics if status == "done" else None,
                     logs if status == "done" else None)
    return {"case": int(case_id), "status": status, "wall_s": rec["wall_s"],
            "error": error.splitlines()[0][:200] if error else ""}


def run_cases(spec_data: dict, case_ids, out: str) -> list:
    """The Dask task: one case (NumPy) or the seeds of one grid point
    (``ensemble``: one vmapped JAX run). Returns their records."""
    if spec_data.get("ensemble"):
        from .ensemble import run_group
        return run_group(spec_data, list(case_ids), out)
    return [run_case(spec_data, cid, out) for cid in case_ids]


def task_groups(spec: Spec, todo) -> list:
    """Case ids per task: one each, or the cases of a grid point together
    when the sweep runs seeds as ensembles."""
    todo = [int(c) for c in todo]
    if not spec.data.get("ensemble"):
        return [[c] for c in todo]
    groups: dict = {}
    nseeds = len(spec.seeds)
    for c in todo:
        groups.setdefault(c // nseeds, []).append(c)
    return list(groups.values())


# ------------------------------------------------------------------ clients
@contextlib.contextmanager
def client_for(scheduler=None, workers=None, dashboard=False):
    """A ``dask.distributed.Client``: ``None`` starts (and afterwards closes)
    a LocalCluster of ``workers`` single-threaded processes on 127.0.0.1
    (default: one per core); an address string connects to a running
    scheduler; a Client is used as it is."""
    try:
        import dask
        from dask.distributed import Client, LocalCluster
    except ImportError as e:  # pragma: no cover - the extra is missing
        raise SweepError("sweeps need Dask: pip install 'avblocks[sweep]'") from e
    if scheduler is not None and workers is not None:
        raise SweepError("workers= only sizes the LocalCluster avblocks starts; "
                         "with scheduler= the cluster decides", found=workers)
    if isinstance(scheduler, Client):
        yield scheduler
        return
    if isinstance(scheduler, str):
        try:
            client = Client(scheduler, timeout="20s")
        except OSError as e:
            raise SweepError(f"cannot reach the Dask scheduler at '{scheduler}': {e}",
                             hint="start one with `dask scheduler` and `dask worker "
                                  "ADDRESS`, or leave scheduler=None for a local "
                                  "cluster") from None
        try:
            yield client
        finally:
            client.close()
        return
    if scheduler is not None:
        raise SweepError("scheduler must be None, an address 'tcp://host:8786' or a "
                         "dask.distributed.Client", found=type(scheduler).__name__)
    n = int(workers) if workers is not None else (os.cpu_count() or 1)
    if n < 1:
        raise SweepError("workers must be >= 1", found=workers)
    # the scheduler's HTTP server (health checks; the dashboard only when asked)
    # on a free loopback port, never a fixed one other programs may hold
    # a case is one long Python loop: the workers' statistical profiler (a
    # stack sample every 10 ms) only costs CPU here
    with dask.config.set({"distributed.worker.profile.enabled": False}):
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                               host="127.0.0.1", dashboard_address=None,
                               scheduler_kwargs={"dashboard_address": "127.0.0.1:0",
                                                 "dashboard": bool(dashboard)},
                               silence_logs=logging.ERROR)
    client = Client(cluster)
    try:
        yield client
    finally:
        client.close()
        cluster.close()


# ------------------------------------------------------------------ driving
class _Progress:
    """Cases done / failed / remaining with an estimate; silent when stderr
    is not a terminal (or ``progress=False``)."""

    def __init__(self, total, enabled):
        if enabled is None:
            enabled = sys.stderr.isatty() and not os.environ.get("CI")
        self.bar = None
        if enabled and total:
            from tqdm import tqdm
            self.bar = tqdm(total=total, unit="case", desc="sweep", file=sys.stderr,
                            dynamic_ncols=True)
        self.done = self.failed = 0
        self.total = total

    def update(self, status):
        if status == "done":
            self.done += 1
        else:
            self.failed += 1
        if self.bar is not None:
            self.bar.set_postfix(done=self.done, failed=self.failed,
                                 left=self.total - self.done - self.failed, refresh=False)
            self.bar.update(1)

    def close(self):
        if self.bar is not None:
            self.bar.close()


def execute(spec: Spec, todo, out, client, progress=None, on_result=None) -> dict:
    """Run the cases ``todo`` on ``client``; returns counts and wall time."""
    from dask.distributed import as_completed
    groups = task_groups(spec, todo)
    total = sum(len(g) for g in groups)
    t0 = time.perf_counter()
    bar = _Progress(total, progress)
    counts = {"done": 0, "failed": 0, "ran": total}
    if not groups:
        bar.close()
        counts["wall_s"] = 0.0
        return counts
    # the definition (a few kB) travels inside each task rather than scattered
    # once: a scattered copy dies with the workers that hold it
    spec_f = spec.data
    threads = sum(client.nthreads().values()) or 1
    window = max(4, 3 * threads)
    inflight = {}
    it = iter(groups)

    def submit(group):
        fut = client.submit(run_cases, spec_f, group, str(out), pure=False,
                            key=f"avblocks-cases-{spec.data['token']}-{group[0]}-"
                                f"{time.monotonic_ns()}")
        inflight[fut.key] = group
        return fut

    ac = as_completed([submit(g) for g in islice(it, window)])
    try:
        for fut in ac:
            group = inflight.pop(fut.key)
            try:
                recs = fut.result()
            except Exception as e:  # noqa: BLE001 - KilledWorker and the like
                text = store.failure_text(e)
                recs = []
                for cid in group:
                    values, seed = spec.case(cid)
                    store.write_case(out, cid, {
                        "status": "failed", "error": text, "wall_s": math.nan,
                        "seed": int(seed), "values": {k: values[k] for k in spec.grid},
                        "worker": "client"})
                    recs.append({"case": cid, "status": "failed",
                                 "error": text.splitlines()[0]})
            fut.release()
            for rec in recs:
                counts[rec["status"]] += 1
                bar.update(rec["status"])
                if on_result is not None:
                    on_result(rec)
            nxt = next(it, None)
            if nxt is not None:
                ac.add(submit(nxt))
    finally:
        bar.close()
        for f in list(getattr(ac, "futures", ())):
            f.cancel()
    counts["wall_s"] = time.perf_counter() - t0
    return counts
