"""One task = the seeds of one grid point, run as one vmapped JAX ensemble.

``av.sweep(..., ensemble=True)`` groups the cases of each grid point into
one task. The task builds each seed's diagram with NumPy (the scenario's
set-up is ordinary Python), takes from each its numeric parameters
(``compiled.param_values()``, with the grid's block parameters on top) and
its initial states, compiles the first diagram once with
:func:`avblocks.compile` and runs every seed through
``runner.ensemble(seeds, params=..., x0=...)`` (per-run values on a leading
axis). Each run's slice of the logs goes through the same metric functions
and into the same store layout as the NumPy path.

It needs the diagram to be traceable (every block ``traceable = True``;
of the built-in scenarios ``waypoints``, ``nest``, ``honeybee``, ``flocking``,
``swap`` and ``formation`` are) and the seeds of a grid
point to share its structure (same agent count, same blocks): seeds change
values, not shapes. Metrics agree with the NumPy path to round-off (float64),
not bit for bit; they are the same whether a case runs in a sweep or is
resumed only as long as it is run in a batch of the same size.
"""

from __future__ import annotations

import time

import numpy as np

from . import store
from .spec import Spec, SweepError, cached_spec


def check_traceable(diagram):
    """Raise :class:`SweepError` naming the first block JAX cannot trace."""
    cd = diagram.build()
    for name, b in zip(cd.names, cd.blocks):
        if not getattr(b, "traceable", True):
            raise SweepError(f"ensemble=True needs a traceable diagram; block '{name}' "
                             f"({type(b).__name__}) runs NumPy-only code",
                             hint="run this sweep without ensemble (one NumPy run per "
                                  "case)")
    return cd


def _stack(values):
    return np.stack([np.asarray(v) for v in values])


def compute_group(spec: Spec, case_ids):
    """``{case_id: (metrics, logs) or exception}`` for the cases of one
    grid point, run as one ensemble."""
    import avblocks as av

    from ..core.results import Results
    from ..core.simulator import Simulator
    out, built = {}, []
    for cid in case_ids:
        try:
            d, sim = spec.build(cid)
            cd = check_traceable(d)
            built.append((cid, d, cd, sim))
        except Exception as e:  # noqa: BLE001 - recorded per case
            out[cid] = e
    if not built:
        return out
    _, d0, cd0, sim0 = built[0]
    t_final = float(sim0.get("t_final", 10.0))
    dt = float(sim0.get("dt", 0.01))
    solver = sim0.get("solver", "rk4")
    log = sim0.get("log")
    want = spec.data.get("log")
    if want and want != ["*"] and log is not None:
        names = [p if isinstance(p, str) else p.path for p in log]
        log = list(log) + [p for p in want if p not in names]
    params, x0 = {}, {}
    for _cid, _d, cd, sim in built:
        vals = dict(cd.param_values())
        for k, v in (sim.get("params") or {}).items():
            # a scalar given for a per-agent parameter: its full shape, so the
            # stacked value's leading axis is unambiguously the run axis
            vals[k] = np.broadcast_to(np.asarray(v, float), np.shape(vals[k]))
        for k, v in vals.items():
            params.setdefault(k, []).append(v)
        states = Simulator(cd, dt, solver, seed=int(sim["seed"])).initial_states()
        for name, blk, x in zip(cd.names, cd.blocks, states):
            for k, v in x.items():
                if k in blk._random:    # random keys come from the seeds
                    continue
                x0.setdefault(f"{name}.{k}", []).append(v)
    try:
        runner = av.compile(d0, t_final, dt, solver, log=log,
                            log_every=int(sim0.get("log_every") or 1), seed=int(sim0["seed"]))
        seeds = [int(sim["seed"]) for *_, sim in built]
        kw = {"params": {k: _stack(v) for k, v in params.items()},
              "x0": {k: _stack(v) for k, v in x0.items()}}
        ens = runner.ensemble(seeds=seeds, **kw)
    except Exception as e:  # noqa: BLE001 - the whole group fails alike
        for cid, *_ in built:
            out[cid] = e
        return out
    every = int(spec.data.get("log_every") or 1)
    for r, (cid, *_rest) in enumerate(built):
        res = Results(ens.t, {k: v[r] for k, v in ens.data.items()}, ens.ports,
                      {**ens.meta, "run": r}, ens.aliases)
        try:
            metrics = {n: np.asarray(fn(res)) for n, fn in spec.metric_fns().items()}
            logs = None
            if want:
                keys = list(res.keys()) if want == ["*"] else want
                logs = {"time": res.t[::every], **{k: res[k][::every] for k in keys}}
            out[cid] = (metrics, logs)
        except Exception as e:  # noqa: BLE001
            out[cid] = e
    return out


def run_group(spec_data: dict, case_ids, out: str) -> list:
    """The Dask task of an ensemble sweep: run and write one grid point."""
    spec = cached_spec(spec_data)
    t0 = time.perf_counter()
    results = compute_group(spec, case_ids)
    wall = (time.perf_counter() - t0) / max(1, len(case_ids))
    recs = []
    for cid in case_ids:
        values, seed = spec.case(cid)
        r = results[cid]
        ok = not isinstance(r, BaseException)
        err = "" if ok else store.failure_text(r)
        rec = {"status": "done" if ok else "failed", "error": err, "wall_s": wall,
               "seed": int(seed), "values": {k: values[k] for k in spec.grid},
               "ensemble": len(case_ids)}
        store.write_case(out, cid, rec, r[0] if ok else None, r[1] if ok else None)
        recs.append({"case": int(cid), "status": rec["status"], "wall_s": wall,
                     "error": err.splitlines()[0][:200] if err else ""})
    return recs
