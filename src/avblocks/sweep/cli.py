"""``avblocks sweep``: the command-line face of :func:`avblocks.sweep`.

    avblocks sweep formation --grid gain=0.5,1,2 --grid speed=0.4,0.8 --seeds 20 \\
        --out sweep.zarr [--metric final_error] [--scheduler tcp://host:8786] [--workers 2]
    avblocks sweep --resume sweep.zarr
    avblocks sweep my_scenario.py --resume sweep.zarr     # a sweep of a Python file
"""

from __future__ import annotations

import sys

import numpy as np

from .spec import SweepError


def parse_grid(items) -> dict:
    """``["k=0.5,1,2", "n=2:8:4"]`` -> ``{"k": [0.5, 1, 2], "n": [2., 4., 6., 8.]}``.
    Values are read as YAML scalars; ``lo:hi:n`` is ``n`` evenly spaced values."""
    import yaml

    from ..scenarios.files import yaml_value
    grid = {}
    for it in items or []:
        if "=" not in it:
            raise SweepError(f"--grid needs name=v1,v2,... found '{it}'",
                             hint="e.g. --grid gain=0.5,1,2 or --grid gain=0.5:2:4")
        k, v = (s.strip() for s in it.split("=", 1))
        if k in grid:
            raise SweepError(f"--grid '{k}' is given twice")
        parts = v.split(":")
        if len(parts) == 3 and "," not in v:
            try:
                lo, hi, n = float(parts[0]), float(parts[1]), int(parts[2])
            except ValueError:
                raise SweepError(f"--grid {k}={v}: lo:hi:n needs two numbers and a "
                                 "count") from None
            from .store import MAX_CASES
            if not 1 <= n <= MAX_CASES or not (np.isfinite(lo) and np.isfinite(hi)):
                raise SweepError(f"--grid {k}={v}: lo:hi:n needs finite numbers and a count "
                                 f"from 1 to {MAX_CASES:,}")
            grid[k] = [float(x) for x in np.linspace(lo, hi, n)]
            continue
        vals = []
        for s in v.split(","):
            s = s.strip()
            if not s:
                raise SweepError(f"--grid {k}={v} has an empty value")
            try:
                vals.append(yaml_value(s, f"--grid {k}"))
            except yaml.YAMLError:
                vals.append(s)
        grid[k] = vals
    return grid


def add_parser(sub):
    """Add the ``sweep`` subcommand to the ``avblocks`` parser."""
    sw = sub.add_parser(
        "sweep", help="run a scenario over a parameter grid x seeds on Dask",
        description="Run a scenario over a grid of parameters and seeds on a Dask "
                    "cluster (a local one by default); results go to a Zarr store.")
    sw.add_argument("target", nargs="?",
                    help="built-in scenario name or file (with --resume: the Python "
                         "scenario file the stored sweep ran, which a store never names "
                         "for you)")
    sw.add_argument("--grid", action="append", metavar="NAME=V1,V2,...",
                    help="a grid dimension (repeatable): scenario parameter, "
                         "simulation.<key> or block.param; lo:hi:n for n values")
    sw.add_argument("--set", action="append", metavar="KEY=VALUE",
                    help="a fixed override for every case (repeatable)")
    sw.add_argument("--seeds", type=int, default=1, help="seeds 0..SEEDS-1 (default 1)")
    sw.add_argument("--metric", action="append", metavar="NAME",
                    help="built-in metric (repeatable; default: the scenario's)")
    sw.add_argument("--out", help="Zarr store (default sweep.zarr)")
    sw.add_argument("--scheduler", metavar="ADDRESS",
                    help="a running Dask scheduler, e.g. tcp://10.0.0.5:8786")
    sw.add_argument("--workers", type=int,
                    help="worker processes of the local cluster (default: one per core)")
    sw.add_argument("--log", action="append", metavar="PORT",
                    help="also store this logged port per case (repeatable; 'all')")
    sw.add_argument("--log-every", type=int, default=1, dest="log_every",
                    help="decimation of the stored logs")
    sw.add_argument("--ensemble", action="store_true",
                    help="run the seeds of each grid point as one vmapped JAX ensemble "
                         "(traceable scenarios, e.g. waypoints)")
    sw.add_argument("--resume", metavar="STORE", help="finish the sweep in STORE")
    sw.add_argument("--retry-failed", action="store_true", dest="retry_failed",
                    help="with --resume: also rerun the failed cases")
    sw.add_argument("--metrics-module", action="append", metavar="MODULE",
                    dest="metrics_module",
                    help="with --resume: a module the stored metric references may be "
                         "imported from (repeatable; avblocks' own always may)")
    sw.add_argument("--overwrite", action="store_true", help="replace an existing store")
    sw.add_argument("--no-plot", action="store_true", dest="no_plot",
                    help="do not write the metric plots")
    sw.add_argument("--dashboard", action="store_true",
                    help="serve the local cluster's dashboard on 127.0.0.1")
    sw.add_argument("--quiet", action="store_true", help="no progress bar")
    sw.set_defaults(fn=cmd_sweep)
    return sw


def cmd_sweep(args):
    from ..scenarios.targets import parse_overrides
    from . import resume_sweep, run_sweep
    common = dict(scheduler=args.scheduler, workers=args.workers,
                  progress=False if args.quiet else None, plot=not args.no_plot,
                  dashboard=args.dashboard)
    out = args.resume or args.out or "sweep.zarr"
    try:
        if args.resume:
            if args.grid or args.set or args.metric or args.log:
                raise SweepError("--resume takes the sweep's definition from the store",
                                 hint="give only --resume STORE (and the scenario when it "
                                      "is a Python file, --scheduler, --workers, "
                                      "--retry-failed, --metrics-module)")
            study = resume_sweep(args.resume, retry_failed=args.retry_failed,
                                 modules=tuple(args.metrics_module or ()),
                                 scenario=args.target, **common)
        else:
            if args.metrics_module:
                raise SweepError("--metrics-module goes with --resume (a new sweep is "
                                 "given its metric functions)")
            if not args.target:
                raise SweepError("name a scenario (or --resume STORE)",
                                 hint="e.g. avblocks sweep formation --grid gain=0.5,1,2")
            log = args.log
            if log and "all" in log:
                log = True
            study = run_sweep(args.target, grid=parse_grid(args.grid), seeds=args.seeds,
                              metrics=args.metric, out=out, fixed=parse_overrides(args.set),
                              log=log, log_every=args.log_every, overwrite=args.overwrite,
                              ensemble=args.ensemble,
                              **common)
    except KeyboardInterrupt:
        print(f"avblocks: interrupted; finished cases are in {out}: "
              f"`avblocks sweep --resume {out}` runs the rest", file=sys.stderr)
        return 130
    run = study.last_run
    print(f"ran {run.get('ran', 0)} cases in {run.get('wall_s', 0.0):.3g} s")
    return 3 if study.counts()["failed"] else 0
