"""``avblocks export RUN --mcap``: a run's folder (or results file) as an MCAP
file for Foxglove.

    avblocks run drone_formation --out runs/sim
    avblocks run drone_formation --robots crazyflies --out runs/flight
    avblocks export runs/sim --mcap                  # -> runs/sim/sim.mcap
    avblocks export runs/flight --mcap               # -> runs/flight/flight.mcap

``RUN`` is the output folder of ``avblocks run`` (its ``results.nc``, the
outcome line of its ``summary.json`` and, after a flight, its
``flight-log.jsonl``) or a results file (``.nc``/``.zarr``). The obstacles
and the leader links come from the scenario: ``--scenario`` (a built-in
name or a scenario file), else the built-in named in ``summary.json`` when
there is one (a name the folder gives is only ever looked up among the
built-ins, never opened as a path). The file is written by
:func:`avblocks.foxglove.write_results` (the ``foxglove`` extra).
"""

from __future__ import annotations

import json
from pathlib import Path

from ..core.errors import AvError

#: largest summary.json read [bytes]
MAX_SUMMARY = 1024**2


def add_parser(sub):
    ex = sub.add_parser("export", help="write a run's results as an MCAP file (Foxglove)")
    ex.add_argument("run", help="the output folder of `avblocks run`, or a results file")
    ex.add_argument("--mcap", action="store_true", required=True,
                    help="write MCAP (Foxglove's schemas; the only format so far)")
    ex.add_argument("-o", "--output", help="the .mcap file (default: RUN/<prefix>.mcap)")
    ex.add_argument("--prefix", help="topic and frame prefix (default: 'flight' for a run "
                                     "with a flight log, else 'sim')")
    ex.add_argument("--scenario", help="the scenario whose obstacles and leader links to "
                                       "draw (built-in name or file)")
    ex.add_argument("--every", type=int, default=1, help="write every N-th sample")
    ex.add_argument("--start", type=float, default=0.0,
                    help="Unix time [s] of the run's t = 0 (default 0: runs and flights "
                         "line up)")
    ex.set_defaults(fn=cmd_export)
    return ex


def _summary(folder: Path) -> dict:
    """The run's summary.json (a file someone may have sent: read as data,
    within a size limit), or {}."""
    p = folder / "summary.json"
    if not p.is_file():
        return {}
    if p.stat().st_size > MAX_SUMMARY:
        raise AvError(f"'{p}' is too large for a run summary",
                      expected=f"<= {MAX_SUMMARY} bytes", found=p.stat().st_size)
    try:
        s = json.loads(p.read_text(encoding="utf-8"))
    except (ValueError, UnicodeDecodeError, RecursionError) as e:
        raise AvError(f"'{p}' is not a run summary: {e}") from None
    return s if isinstance(s, dict) else {}


def _world(scenario):
    """``(obstacles, links)`` of a scenario: its movie's obstacles or the
    first block that has a world; the leader tree of a LeaderFollower."""
    import numpy as np

    from ..scenarios.targets import load_any
    d, _sim, _name, movie = load_any(scenario, {}, None)
    obstacles = (movie or {}).get("obstacles") or (movie or {}).get("world")
    if obstacles is None:
        obstacles = next((h.block.world for h in d.blocks.values()
                          if getattr(h.block, "world", None) is not None), None)
    links = None
    for h in d.blocks.values():
        leader = getattr(h.block, "leader", None)
        if isinstance(leader, np.ndarray) and leader.ndim == 1 and leader.dtype.kind in "iu":
            follow = np.flatnonzero(leader >= 0)
            links = np.column_stack([follow, leader[follow]])
            break
    return obstacles, links


def cmd_export(args):
    from ..core.results import Results
    from ..scenarios import builtin_scenarios
    run = Path(args.run)
    if run.is_dir():
        folder = run
        results_file = run / "results.nc"
        if not results_file.exists() and (run / "results.zarr").exists():
            results_file = run / "results.zarr"
    elif run.suffix in (".nc", ".zarr"):
        folder, results_file = run.parent, run
    else:
        raise AvError(f"'{run}' is neither a run folder nor a results file",
                      expected="the --out folder of `avblocks run`, or a .nc/.zarr file")
    if not results_file.exists():
        raise AvError(f"no results in '{folder}'", expected="results.nc (written by "
                      "`avblocks run`)")
    res = Results.load(results_file)
    summary = _summary(folder)
    flight_log = folder / "flight-log.jsonl"
    flight_log = flight_log if flight_log.is_file() else None
    prefix = args.prefix or ("flight" if flight_log is not None else "sim")
    scenario = args.scenario
    if scenario is None and isinstance(summary.get("scenario"), str) \
            and summary["scenario"] in builtin_scenarios():
        scenario = summary["scenario"]
    obstacles = links = None
    if scenario is not None:
        obstacles, links = _world(scenario)
    outcome = summary.get("outcome") if isinstance(summary.get("outcome"), str) else None
    out = Path(args.output) if args.output else folder / f"{prefix}.mcap"
    from ..foxglove import write_results
    path = write_results(res, out, prefix=prefix, start=args.start, outcome=outcome,
                         obstacles=obstacles, links=links, every=args.every,
                         flight_log=flight_log)
    what = f"{len(res.t)} samples" + (", the flight log" if flight_log else "")
    print(f"wrote {path} ({what}; topics under /{prefix}/)")
    return 0
