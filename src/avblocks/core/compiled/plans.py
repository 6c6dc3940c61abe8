"""Static plans of the neighbour searches blocks own, and overflow handling.

A traced search has static shapes (see :mod:`avblocks.utility.spatial`):
its candidate capacity and hit width are fixed before tracing. The compiled
engine (:func:`avblocks.compile`):

1. **plans** every search a block owns (``block.searches()``, or each
   attribute that is a ``NeighborSearch``; see
   :func:`avblocks.core.diagnostics.searches_of`) from the points it
   searches at ``t0`` the first time the block is compiled: the block's
   input ``points`` computed by the NumPy engine from the initial states
   through only the blocks upstream of it (:func:`points_at_t0`: the
   searching block and what follows it are not evaluated), or, when the
   search's ``points`` names a parameter such as fixed targets, that
   parameter's value; unless the user fixed ``capacity=``. The plan is part
   of the block's structure, so it is part of the compile-cache key; it is
   kept for the block's life and only grows (after an overflow, step 3), so
   a grown plan is not planned away again;
2. during the run, each search call adds what it needed to a running
   maximum the run carries and returns (:mod:`avblocks.core.diagnostics`;
   nothing is called back to the host);
3. after the run, where a search needed more than its plan:

   - ``on_overflow="replan"`` (default): a :class:`RuntimeWarning` names
     the block and the sizes, the search is re-planned with the needed size
     times its ``headroom``, the program is compiled again and the run
     repeated. A run may be re-planned :data:`REPLANS` (2) times: the hits
     counted behind an overflowed capacity are an estimate. A run that
     overflows after that raises;
   - ``on_overflow="raise"``: :class:`~avblocks.core.errors.SimulationError`
     naming the block, "capacity" (or "hits", "radius"), needed vs planned.

An ensemble's need is the largest over its runs.

A block whose state shapes follow its plans (the Verlet list of
``environment.Neighbors``) defines ``searches_planned()``; it is called after
every planning and growing, before the program is built.

Plans are kept
--------------
A plan grown after an overflow is kept in a *plan book* under the
diagram's structure without its plans (:func:`~.structure.plan_key`:
block types, wiring, shapes, dtypes and structural values, not numeric
parameters or initial states). Step 1 takes a search's plan from the book
before planning from ``t0``, so a second compile of the same structure
(the same diagram object or one built anew) starts from the grown plan:
no re-plan, and the program the first run compiled after growing. Read,
set and save them with :func:`get_plans`, :func:`set_plans`,
:func:`save_plans` and :func:`load_plans`. A runner with a cache folder
(``compile(..., cache=)``, the user's cache folder by default: see
:mod:`avblocks.core.compiled.persist`) also writes them to disk, one JSON
file per structure in a folder named after the avblocks and JAX versions,
read back (and checked as data) by later processes; so is the verdict that
a use of the structure exchanges data between devices when split (it then
runs on one device from the start). :func:`use_plan_store` overrides the
folder for every runner, or keeps plans in memory only.
"""

from __future__ import annotations

import json
import math
import threading
import warnings
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from .. import diagnostics
from ..errors import ParameterError, SimulationError
from .structure import plan_key, stable_digest

MODES = ("replan", "raise")

#: Re-planning rounds one run may take before an overflow raises (a grown
#: capacity lets more hits through than were counted: a second round)
REPLANS = 2


def check_mode(mode):
    if mode not in MODES:
        raise ParameterError("unknown on_overflow", param="on_overflow",
                             expected=" or ".join(repr(m) for m in MODES), found=mode)
    return mode


def owned(cd):
    """``[(block index, search number, search)]`` of a compiled diagram."""
    out = []
    for i, b in enumerate(cd.blocks):
        for j, s in enumerate(diagnostics.searches_of(b)):
            out.append((i, j, s))
    return out


def plan_searches(cd, *, dt, t0=0.0, seed=0, x0=None, store=None):
    """Plan every search of ``cd`` not fixed by its user: from the plan
    book when it holds a plan of this structure (a grown one, or one read
    from the plan store ``store``, a folder), else from the points each
    search would search at ``t0`` (:func:`points_at_t0`). Returns the
    number planned from ``t0``."""
    searches = owned(cd)
    if searches:
        adopt(cd, store)
    # a search planned before keeps its plan: a run that outgrows it is caught
    # after the run and re-planned (step 3), so a second compile of the same
    # blocks (every ``simulate(backend="jax")`` call) needs no NumPy evaluation
    todo = [(i, s) for i, _, s in searches
            if not getattr(s, "fixed", False) and getattr(s, "cells", None) is None]
    if not todo:
        _planned(cd)
        return 0
    for (i, s), pts in zip(todo, points_at_t0(cd, todo, dt=dt, t0=t0, seed=seed, x0=x0)):
        try:
            s.plan(np.asarray(pts))
        except ParameterError as e:
            if e.param != "points":
                raise
            raise SimulationError(f"the positions its neighbour search is planned from "
                                  f"('{s.points}') must be finite: {e.found}",
                                  block=cd.names[i], time=float(t0)) from None
    _planned(cd)
    return len(todo)


def points_at_t0(cd, todo, *, dt, t0=0.0, seed=0, x0=None):
    """The points each search of ``todo`` (``[(block index, search)]``)
    searches at ``t0``: its block's input ``points`` computed by the NumPy
    engine, or the parameter of that name (fixed targets).

    Only what those inputs need is evaluated: the blocks upstream of each
    input through direct-feedthrough wires, from the initial states (a
    block without feedthrough, such as an integrator, gives its output
    from its state alone). The searching blocks themselves and everything
    downstream (the flocking law's pair lists at 10^7 agents: most of the
    minute planning took) are not evaluated."""
    from .. import memo as _memo
    from .. import rng as _rng
    from ..block import Block as _Block
    from ..simulator import Simulator
    names = cd.names
    wanted = []                                 # (block i, source block, output) or None
    for i, s in todo:
        src = cd.sources[i].get(s.points) if s.points in cd.blocks[i]._inputs else None
        params = getattr(cd.blocks[i], "_params", {})
        if src is None and s.points not in params:
            raise ParameterError("a neighbour search names neither an input nor a "
                                 "parameter of its block", block=names[i],
                                 param="points",
                                 expected=sorted(cd.blocks[i]._inputs) + sorted(params),
                                 found=s.points)
        wanted.append(src)
    srcs = [w for w in wanted if w is not None]
    if not srcs:
        return [cd.blocks[i].get_parameter(s.points) for i, s in todo]
    sim = Simulator(cd, dt, "euler", seed=seed, t0=t0, x0=x0, check_finite=False)
    eng = sim.eng
    need = eng.feedthrough_ancestors(j for j, _ in srcs)
    X = [{} for _ in cd.blocks]
    for j in need:                              # states read, never written: no copies
        b = cd.blocks[j]
        x = dict(b._init) if type(b).initial_state is _Block.initial_state \
            else b.initial_state()
        x.update({nm: v for (i, nm), v in sim.x0.items() if i == j})
        for r in b._random:
            x[r] = _rng.key(sim.seed, f"{cd.names[j]}.{r}")
        X[j] = x
    Y = [dict() for _ in cd.blocks]
    token = _memo.activate(sim._memo)
    try:
        for j in eng.with_outputs:              # evaluation order
            if j in need:
                Y[j] = sim._guard(lambda t, X, Y, j=j: eng._out(j, t, X, Y), sim.t0, X, Y)
    finally:
        _memo.deactivate(token)
    return [cd.blocks[i].get_parameter(s.points) if w is None else Y[w[0]][w[1]]
            for (i, s), w in zip(todo, wanted)]


def _planned(cd):
    """Tell the blocks that own searches their plans are set (or grew): a
    block whose state shapes follow a plan (``Neighbors``' Verlet list)
    re-declares them in its ``searches_planned()``."""
    for b in cd.blocks:
        hook = getattr(b, "searches_planned", None)
        if callable(hook):
            hook()


def overflows(cd, needs):
    """``[(block name, search, need, message)]`` of the searches whose need
    exceeds their plan; ``needs`` is ``{(block name, search number):
    [capacity, hits, reach, span]}`` (a run's tally, see
    :meth:`~avblocks.core.compiled.program.Program.needs`)."""
    out = []
    if not needs:
        return out
    for i, j, s in owned(cd):
        v = needs.get((cd.names[i], j))
        if v is None or s.cells is None:
            continue
        need = SimpleNamespace(capacity=int(v[0]), reach=float(v[2]), hits=int(v[1]),
                               span=float(v[3]))
        msg = s.cells.exceeded(need)
        if msg:
            out.append((cd.names[i], s, need, msg))
    return out


def settle(runner, over, rerun):
    """Act on ``over`` (from :func:`overflows`) after a run of ``runner``:
    raise, or grow the plans, rebuild the runner's program and return
    ``rerun()``'s result."""
    names = ", ".join(f"'{n}' ({m})" for n, _, _, m in over)
    mode = getattr(runner, "on_overflow", "replan")
    bad_reach = [n for n, s, need, _ in over
                 if float(need.reach) > s.cells.reach * (1 + 1e-6) or need.span > 1.0]
    rounds = getattr(runner, "_replanned", 0)
    if mode == "raise" or bad_reach or rounds >= REPLANS:
        why = "a compiled neighbour search overflowed its static plan"
        if rounds:
            why += " again after re-planning"
        raise SimulationError(f"{why}: {names}", block=over[0][0],
                              hint="give the block a larger capacity=, or compile with "
                                   "on_overflow='replan' (the default)")
    for _, s, need, _ in over:
        s.cells = s.cells.grown(need, s.headroom)
    _planned(runner.compiled)
    record(runner.compiled, getattr(runner, "plan_store", None))
    warnings.warn(f"compiled run re-planned after a neighbour search overflow: {names}; "
                  "compiling again and repeating the run", RuntimeWarning, stacklevel=3)
    runner._rebuild_program()
    runner._replanned = rounds + 1
    try:
        return rerun()
    finally:
        runner._replanned = rounds


# ------------------------------------------------------------ the plan book

_BOOK: dict = {}            # plan_key -> {(block name, search number): CellList}
_ONE: dict = {}             # plan_key -> uses whose split communicates ("run", ...)
_BOOK_LOCK = threading.Lock()
#: the plan store every runner uses instead of its own (``use_plan_store``):
#: None (each runner's cache folder, :mod:`.persist`), False (none) or a folder
_STORE = {"path": None}
#: plans adopted from the book / read from the store / written to it; entries
#: of the store ignored (damaged or foreign)
STATS = {"adopted": 0, "read": 0, "written": 0, "ignored": 0}

#: the largest plan file read (bytes): a structure's plans are a few hundred
MAX_FILE_BYTES = 1 << 20
_FIELDS = {"reach", "capacity", "hits", "box", "dim", "split"}


def _versions():
    from importlib.metadata import PackageNotFoundError, version
    try:
        __version__ = version("avblocks")
    except PackageNotFoundError:        # pragma: no cover - run from a source tree
        __version__ = "unknown"
    try:
        import jax
        jv = jax.__version__
    except ImportError:                 # pragma: no cover - the jax extra
        jv = "none"
    return f"avblocks-{__version__}_jax-{jv}"


def use_plan_store(path=None):
    """Where every runner keeps grown plans on disk: ``path`` (a folder), in
    a sub-folder named after the avblocks and JAX versions (a new version
    starts empty); ``False``: nowhere (memory only); ``None`` (default):
    each runner in its own cache folder (``compile(..., cache=)``, see
    :mod:`avblocks.core.compiled.persist`). Returns the sub-folder (or None)."""
    if path is None or path is False:
        _STORE["path"] = path
        return None
    p = Path(path) / _versions()
    p.mkdir(parents=True, exist_ok=True)
    _STORE["path"] = p
    return p


def plan_store(root=None):
    """The folder plans are written to and read from by a runner whose cache
    folder is ``root`` (see :func:`use_plan_store`), or None."""
    over = _STORE["path"]
    if over is False:
        return None
    if over is not None:
        return over
    if root is None:
        return None
    p = Path(root) / "plans" / _versions()
    try:
        p.mkdir(mode=0o700, parents=True, exist_ok=True)
    except OSError:
        return None
    return p


def _to_dict(c):
    return {"reach": c.reach, "capacity": c.capacity, "hits": c.hits, "box": c.box,
            "dim": c.dim, "split": c.split}


def _from_dict(d, search):
    """A plan of ``search``'s class (``type(search).plan_type``: core does
    not import the spatial utilities) from a dict of its fields."""
    d = {"reach": search.reach, "box": search.box, "dim": search.dim, **d}
    box = d.get("box")
    return type(search).plan_type(
        float(d["reach"]), None if d.get("capacity") is None else int(d["capacity"]),
        None, None if box is None else tuple(box), int(d.get("dim", 2)),
        None if d.get("hits") is None else int(d["hits"]), int(d.get("split", 2)))


def _as_plan(p, search):
    return _from_dict(p, search) if isinstance(p, dict) else p


def _number(v, kind):
    ok = (type(v) is int if kind is int else type(v) in (int, float)) and \
        math.isfinite(v) and v > 0
    if not ok:
        raise ValueError(f"not a positive {kind.__name__}: {v!r}"[:80])
    return v


def checked_fields(d):
    """The fields of one stored plan, checked as data (types and ranges;
    see :func:`_fits` and :func:`_bounded` for the rest). Raises
    ValueError naming what is wrong."""
    if type(d) is not dict or not set(d) <= _FIELDS:
        raise ValueError(f"a plan is a dict of {sorted(_FIELDS)}")
    out = {}
    for k, v in d.items():
        if k in ("capacity", "hits"):
            out[k] = None if v is None else _number(v, int)
        elif k == "reach":
            out[k] = float(_number(v, float))
        elif k == "dim":
            if v not in (2, 3) or type(v) is not int:
                raise ValueError(f"dim must be 2 or 3: {v!r}"[:80])
            out[k] = v
        elif k == "split":
            if type(v) is not int or not 1 <= v <= 8:
                raise ValueError(f"split must be 1..8: {v!r}"[:80])
            out[k] = v
        elif k == "box":
            if v is not None:
                if type(v) is not list or len(v) not in (2, 3):
                    raise ValueError("box must be a list of 2 or 3 lengths")
                v = [float(_number(b, float)) for b in v]
            out[k] = v
    return out


def _checked_file(data):
    """``(plans, uses that run on one device)`` of a plan file's JSON, each
    entry checked (:func:`checked_fields`); ValueError when the file is
    not one of this version's."""
    if type(data) is not dict or data.get("versions") != _versions():
        raise ValueError("written by another avblocks or JAX version, or not a plan file")
    plans = data.get("plans", {})
    if type(plans) is not dict or len(plans) > 4096:
        raise ValueError("'plans' must be a dict of plans")
    got = {_parse_name(n): checked_fields(v) for n, v in plans.items()}
    one = data.get("one_device", [])
    if type(one) is not list or not all(type(u) is str and len(u) < 64 for u in one):
        raise ValueError("'one_device' must be a list of names")
    return got, set(one)


def _ignored(f, why):
    STATS["ignored"] += 1
    warnings.warn(f"avblocks: ignored the stored plans {f}: {why}; planning afresh",
                  RuntimeWarning, stacklevel=5)


def _file(key, store):
    if store is None:
        return None
    digest = stable_digest(key)
    return None if digest is None else Path(store) / f"{digest}.json"


def _read(f):
    """A plan file's checked contents, ``({}, set())`` when there is none
    (or, with a warning, when it is damaged or foreign: never trusted)."""
    try:
        if not f.is_file():
            return {}, set()
        if f.stat().st_size > MAX_FILE_BYTES:
            raise ValueError(f"larger than {MAX_FILE_BYTES} bytes")
        data = json.loads(f.read_text(encoding="utf-8"))
        got = _checked_file(data)
    except (OSError, ValueError, TypeError, KeyError, RecursionError) as e:
        _ignored(f, f"{type(e).__name__}: {e}"[:200])
        return {}, set()
    STATS["read"] += 1
    return got


def _entry(key, store=None):
    """The book's plans of structure ``key`` (read from the store the first
    time), or an empty dict."""
    with _BOOK_LOCK:
        got = _BOOK.get(key)
    if got:
        return got
    f = _file(key, store)
    got, one = _read(f) if f is not None else ({}, set())
    if one:
        with _BOOK_LOCK:
            _ONE.setdefault(key, set()).update(one)
    if not got and _LOADED:
        got = dict(_LOADED.get(stable_digest(key), {}))
    if not got:
        return {}                       # nothing kept (looked for again next time)
    with _BOOK_LOCK:
        _BOOK.setdefault(key, got)
        return _BOOK[key]


def one_device(cd, use, store=None) -> bool:
    """Whether a program of ``cd``'s structure used as ``use`` ("run",
    "ensemble") is known to exchange data between devices when split
    (learnt by a compile in this process or an earlier one: kept with the
    plans), so it is compiled for one device from the start."""
    key = plan_key(cd)
    with _BOOK_LOCK:
        if use in _ONE.get(key, ()):
            return True
    f = _file(key, store)
    if f is not None:
        _, one = _read(f)
        with _BOOK_LOCK:
            _ONE.setdefault(key, set()).update(one)
            return use in _ONE[key]
    return False


def remember_one_device(cd, use, store=None):
    """Keep that ``cd``'s structure used as ``use`` runs on one device
    (see :func:`one_device`), in the book and the store."""
    key = plan_key(cd)
    with _BOOK_LOCK:
        _ONE.setdefault(key, set()).add(use)
    _write(cd, key, store)


def _parse_name(name):
    block, _, j = str(name).rpartition("/")
    return (block, int(j)) if block and j.isdigit() else (str(name), 0)


def _name(block, j):
    return f"{block}/{j}"


def _fits(plan, s):
    return (plan.reach == s.reach and plan.dim == s.dim
            and (plan.box is None) == (s.box is None)
            and (s.box is None or tuple(plan.box) == tuple(float(b) for b in s.box)))


def _larger(a, b):
    """Plan ``a`` has room for everything ``b`` has (and differs)."""
    def ge(x, y):
        return x is None or (y is not None and x >= y)
    return a != b and ge(a.capacity, b.capacity) and ge(a.hits, b.hits)


def _points(cd, i, s):
    """How many points search ``s`` of block ``i`` searches (its input's or
    parameter's leading length), or None."""
    b = cd.blocks[i]
    port = getattr(b, "_inputs", {}).get(s.points)
    if port is not None and getattr(port, "shape", None):
        return int(port.shape[0])
    spec = getattr(b, "_params", {}).get(s.points)
    if spec is not None and getattr(spec, "shape", None):
        return int(spec.shape[0])
    return None


def _bounded(p, n):
    """A plan's sizes are possible for ``n`` points: no plan needs more
    candidates or hits than a few times the points (planned with headroom,
    at least :func:`plan_cells`' minimum): a stored plan larger than that
    is not one this search grew."""
    if n is None:
        return True
    top = max(64, 4 * n)
    return all(v is None or v <= top for v in (p.capacity, p.hits))


def adopt(cd, store=None):
    """Give each search of ``cd`` not fixed by its user the book's plan of
    its structure when the book has one with at least its room. Returns
    the number adopted. A plan that is not this search's (another reach,
    box or dimension; sizes no run of it could need) is ignored with a
    warning."""
    key = plan_key(cd)
    entry = _entry(key, store)
    n = 0
    if entry:
        for i, j, s in owned(cd):
            p = entry.get((cd.names[i], j))
            if p is None or getattr(s, "fixed", False):
                continue
            try:
                p = _as_plan(p, s)
                if not _fits(p, s):
                    raise ValueError(f"it is for reach {p.reach}, box {p.box}, dim "
                                     f"{p.dim}, not {s.reach}, {s.box}, {s.dim}")
                if not _bounded(p, _points(cd, i, s)):
                    raise ValueError(f"its sizes (capacity {p.capacity}, hits {p.hits}) "
                                     f"are beyond {_points(cd, i, s)} points")
            except (ParameterError, KeyError, TypeError, ValueError) as e:
                STATS["ignored"] += 1
                warnings.warn(f"avblocks: ignored a kept plan of '{cd.names[i]}': {e}; "
                              "planning afresh", RuntimeWarning, stacklevel=4)
                continue
            if s.cells is None or _larger(p, s.cells):
                s.cells = p
                n += 1
        if n:
            _planned(cd)
            STATS["adopted"] += n
    return n


def record(cd, store=None):
    """Put the current plans of ``cd``'s searches in the book (and the
    store ``store``, a folder, when given)."""
    key = plan_key(cd)
    entry = {(cd.names[i], j): s.cells for i, j, s in owned(cd)
             if s.cells is not None and not getattr(s, "fixed", False)}
    if not entry:
        return
    with _BOOK_LOCK:
        _BOOK[key] = {**_BOOK.get(key, {}), **entry}
    _write(cd, key, store)


def _write(cd, key, store):
    """The book's plans and one-device uses of ``key``, to its file (atomic)."""
    f = _file(key, store)
    if f is None:
        return
    with _BOOK_LOCK:
        full = dict(_BOOK.get(key, {}))
        one = sorted(_ONE.get(key, ()))
    from ..atomic import atomic_path
    try:
        with atomic_path(f) as tmp:
            Path(tmp).write_text(json.dumps({
                "versions": _versions(),
                "plans": {_name(*k): (v if isinstance(v, dict) else _to_dict(v))
                          for k, v in sorted(full.items())},
                "one_device": one}, indent=1), encoding="utf-8")
        STATS["written"] += 1
    except Exception as e:   # noqa: BLE001 - a cache never fails a run
        warnings.warn(f"could not store the grown plans in {f.parent}: {e}",
                      RuntimeWarning, stacklevel=3)


def forget_plans():
    """Empty this process's plan book (plans loaded with :func:`load_plans`
    included; the store on disk and the plans the searches hold are kept)."""
    with _BOOK_LOCK:
        _BOOK.clear()
        _ONE.clear()
        _LOADED.clear()


def _compiled_of(diagram):
    from ..diagram import CompiledDiagram, Diagram
    if isinstance(diagram, CompiledDiagram):
        return diagram
    if isinstance(diagram, Diagram):
        return diagram.build()
    runner = getattr(diagram, "compiled", None)        # a Runner
    if isinstance(runner, CompiledDiagram):
        return runner
    raise ParameterError("expected a Diagram, a compiled diagram or a Runner",
                         param="diagram", found=type(diagram).__name__)


def get_plans(diagram) -> dict:
    """The plans of a diagram's neighbour searches: ``{"block/j": CellList}``
    (``j`` numbers the block's searches from 0), each the search's own plan
    or, where it has none yet, the book's for this structure (None when
    neither: planned at the next compile). ``diagram``: a ``Diagram``,
    its compiled form or a ``Runner``."""
    cd = _compiled_of(diagram)
    entry = _entry(plan_key(cd), default_store())
    out = {}
    for i, j, s in owned(cd):
        p = s.cells if s.cells is not None else entry.get((cd.names[i], j))
        out[_name(cd.names[i], j)] = None if p is None else _as_plan(p, s)
    return out


def set_plans(diagram, new):
    """Set the plans of a diagram's searches, ``{"block/j": plan}`` (or
    ``"block"`` for its first search), where a plan is a ``CellList`` or a
    dict with ``capacity`` and/or ``hits`` (the rest from the search). They
    are also put in the book (and the store), so every diagram of this
    structure compiles with them. A search keeps them until an overflow
    grows them (the user's fixed ``capacity=`` searches cannot be set)."""
    cd = _compiled_of(diagram)
    by_name = {(cd.names[i], j): s for i, j, s in owned(cd)}
    for name, p in dict(new).items():
        k = _parse_name(name)
        s = by_name.get(k)
        if s is None:
            raise ParameterError("no such neighbour search", param="plans",
                                 expected=sorted(_name(*k) for k in by_name), found=name)
        if getattr(s, "fixed", False):
            raise ParameterError("this search's capacity was fixed by its block's "
                                 "capacity=", block=k[0], param="plans", found=name)
        if isinstance(p, dict):
            cur = s.cells
            d = _to_dict(cur) if cur is not None else {}
            d.update(p)
            p = _from_dict(d, s)
        if not _fits(p, s):
            raise ParameterError("the plan is for another search (reach, box or dim "
                                 "differ)", block=k[0], param="plans",
                                 expected=f"reach {s.reach}, box {s.box}, dim {s.dim}",
                                 found=f"reach {p.reach}, box {p.box}, dim {p.dim}")
        s.cells = p
    _planned(cd)
    record(cd, default_store())


def save_plans(path):
    """Write every plan of the book (this process's, and those read from
    the store) to the JSON file ``path``; structures that cannot be named
    across processes (a ``lambda`` in a block) are left out."""
    out = {}
    with _BOOK_LOCK:
        items = list(_BOOK.items())
    for key, entry in items:
        digest = stable_digest(key)
        if digest is not None and entry:
            out[digest] = {_name(*k): (v if isinstance(v, dict) else _to_dict(v))
                           for k, v in sorted(entry.items())}
    Path(path).write_text(json.dumps({"versions": _versions(), "structures": out},
                                     indent=1))
    return len(out)


def load_plans(path):
    """Read plans written by :func:`save_plans`: a diagram whose structure
    is among them compiles with its plan. Returns the number of structures.
    The file is data, checked as the plan store's files are (a
    :class:`ParameterError` names what is wrong); plans that do not fit a
    search are ignored with a warning when it compiles."""
    f = Path(path)
    try:
        if f.stat().st_size > 64 * MAX_FILE_BYTES:
            raise ValueError(f"larger than {64 * MAX_FILE_BYTES} bytes")
        data = json.loads(f.read_text(encoding="utf-8"))
        structures = data.get("structures", {}) if type(data) is dict else None
        if type(structures) is not dict:
            raise ValueError("'structures' must be a dict")
        got = {}
        for d, e in structures.items():
            if type(d) is not str or type(e) is not dict:
                raise ValueError("each structure is a digest and a dict of plans")
            got[d] = {_parse_name(n): checked_fields(v) for n, v in e.items()}
    except (OSError, ValueError, TypeError, RecursionError) as e:
        raise ParameterError(f"not a plans file: {e}"[:300], param="path",
                             found=str(path)) from None
    with _BOOK_LOCK:
        _LOADED.update(got)
    return len(got)


def default_store():
    """The plan store of a runner compiled with the default ``cache=None``
    (:mod:`avblocks.core.compiled.persist`), or None."""
    from . import persist
    return plan_store(persist.usable(persist.resolve(None)))


_LOADED: dict = {}          # stable digest -> plans, from load_plans()
