"""Validation: a document built with the library's own checks, every error
mapped to the block, port, parameter, wire or cycle it names.

:func:`check_document` builds a scenario mapping as ``avblocks run`` would;
when that fails it builds the blocks one by one, then the wires one by one,
then lists unconnected inputs, so the page can mark as many errors as the
library can tell. :class:`Checker` remembers the findings of a few recent
scenarios (a layout-only edit, such as a block moved, is answered without
building again).
"""

from __future__ import annotations

import copy
import json
import threading

from ..core.errors import AlgebraicLoopError, AvError, ScenarioError
from .documents import scenario_data
from .errors import EditorError

#: Validations remembered by their scenario (a layout-only edit, such as a
#: block moved, is answered without building again).
CHECK_CACHE = 8


def _where(entry):
    """``(block, param, wire index)`` named by a loader entry such as
    ``blocks.drive.gain`` or ``wires[3]``."""
    import re
    if not entry:
        return None, None, None
    m = re.match(r"^blocks\.([A-Za-z_][A-Za-z0-9_]*)(?:\.([A-Za-z_][A-Za-z0-9_]*))?", entry)
    if m:
        param = m.group(2)
        return m.group(1), (None if param == "type" else param), None
    m = re.match(r"^wires\[(\d+)\]", entry)
    if m:
        return None, None, int(m.group(1))
    m = re.match(r"^params\.(.+)$", entry)
    if m:
        b, _, p = m.group(1).partition(".")
        return b or None, p or None, None
    return None, None, None


def error_record(e: AvError, *, block=None, port=None, param=None, wire=None,
                 cycle=None) -> dict:
    """The error record of API.md for a library error: its own message and
    kind, and what it names (the error's structured context first, then the
    place the editor knows it came from)."""
    inner = e.__context__ if isinstance(e, ScenarioError) else None
    src = inner if isinstance(inner, AvError) else e
    eb, ep, ew = _where(getattr(e, "entry", None))
    message = str(e)
    where = "".join(f"{x}: " for x in (getattr(e, "file", None), getattr(e, "entry", None))
                    if x is not None)
    if src is not e and e.cause == where + str(src):
        message = str(src)             # the loader only added where it was
    elif isinstance(e, ScenarioError) and e.file and message.startswith(f"{e.file}: "):
        message = message[len(e.file) + 2:]    # the page knows which file it is
    rec = {
        "message": message,
        "kind": type(src).__name__,
        "block": block or eb or _leaf(getattr(src, "block", None)),
        "port": port or getattr(src, "port", None),
        "param": param or getattr(src, "param", None) or ep,
        "wire": wire,
        "cycle": cycle,
        "field": None,
        "refs": [],
    }
    if ew is not None and rec["wire"] is None:
        rec["wire"] = ew
    return rec


def _leaf(block):
    return None if block is None else str(block)


class _Collector:
    """Builds a document into a diagram piece by piece, collecting every
    error the library raises on the way (see :func:`check_document`)."""

    def __init__(self, data, source, out, modules=()):
        from ..scenarios.loader import Scenario
        self.data = data
        self.sc = Scenario(data, source, modules=tuple(modules))
        self.out = out
        self.errors = []

    def add(self, e, **where):
        rec = error_record(e, **where)
        key = (rec["message"], rec["block"], rec["port"], str(rec["wire"]))
        if key not in {(r["message"], r["block"], r["port"], str(r["wire"]))
                       for r in self.errors}:
            self.errors.append(rec)

    def blocks(self):
        """Each block constructed on its own (the loader's rules: registry
        types only, known parameters, values resolved, files confined)."""
        import inspect

        from ..core.diagram import Diagram
        from ..core.errors import did_you_mean
        from ..scenarios.loader import block_registry
        sc = self.sc
        sc.params = dict(self.data.get("parameters") or {})
        sc._generated_bytes = 0
        reg = block_registry(code_blocks=True, modules=sc.modules, interfaces=True)
        d = Diagram(sc.name if str(sc.name).isidentifier() else None)
        for name, spec in (self.data.get("blocks") or {}).items():
            where = f"blocks.{name}"
            try:
                if not isinstance(spec, dict) or "type" not in spec:
                    raise ScenarioError("each block needs a 'type'", file=sc.source,
                                        entry=where, hint="e.g. type: vehicles.Unicycle")
                typ = spec["type"]
                if not isinstance(typ, str) or typ not in reg:
                    raise ScenarioError(f"unknown block type '{typ}'", file=sc.source,
                                        entry=f"{where}.type",
                                        hint=did_you_mean(typ, reg)
                                        + "run `avblocks list --blocks` for the types")
                cls = reg[typ]
                sig = inspect.signature(cls.__init__)
                accepted = [p for p in sig.parameters if p != "self"]
                has_var = any(p.kind == p.VAR_KEYWORD for p in sig.parameters.values())
                bad = [k for k in spec if k != "type" and k not in accepted
                       and not has_var]
                for k in bad:
                    self.add(ScenarioError(f"unknown parameter '{k}' for {typ}",
                                           file=sc.source, entry=f"{where}.{k}",
                                           hint=did_you_mean(k, accepted)
                                           + f"{typ} takes {accepted}"),
                             block=name, param=k)
                if bad:
                    continue
                kwargs = {}
                failed = False
                for k, v in spec.items():
                    if k == "type":
                        continue
                    try:
                        kwargs[k] = sc._value(v, f"{where}.{k}")   # as the loader does
                    except AvError as e:
                        self.add(e, block=name, param=k)
                        failed = True
                if failed:
                    continue
                kwargs = sc._confine(kwargs, where, self.out)
                try:
                    block = cls(**kwargs)
                except AvError as e:
                    self.add(e, block=name, param=getattr(e, "param", None))
                    continue
                except Exception as e:  # noqa: BLE001 - a constructor's own failure
                    self.add(ScenarioError(f"{typ}: {type(e).__name__}: {e}",
                                           file=sc.source, entry=where,
                                           hint=f"{typ} takes {accepted}"), block=name)
                    continue
                d.add(block, name=name)
            except AvError as e:
                self.add(e, block=name)
        return d

    def wires(self, d):
        """Each wire connected on its own (one driver per input, port names,
        shapes, dtypes and agent counts as far as they are known)."""
        for j, w in enumerate(self.data.get("wires") or []):
            if not (isinstance(w, list) and len(w) == 2
                    and all(isinstance(s, str) for s in w)):
                self.add(ScenarioError(f'a wire is ["block.output", "block.input"], '
                                       f"found {w!r:.80}", file=self.sc.source,
                                       entry=f"wires[{j}]"), wire=j)
                continue
            refs = []
            drawn = self.data.get("blocks") or {}
            unknown = [s.partition(".")[0] for s in w if s.partition(".")[0] not in drawn]
            if unknown:
                from ..core.errors import WiringError, did_you_mean
                self.add(WiringError(f"wire names unknown block '{unknown[0]}'",
                                     hint=did_you_mean(unknown[0], drawn)
                                     + f"blocks: {sorted(drawn)}"), wire=j)
                continue
            for s in w:
                b, _, p = s.partition(".")
                if b not in d.blocks:
                    break                       # that block has its own error
                try:
                    refs.append(d[b].port(p))
                except AvError as e:
                    self.add(e, block=b, port=p, wire=j)
                    break
            if len(refs) != 2:
                continue
            try:
                d.connect(*refs)
            except AvError as e:
                self.add(e, block=refs[1].handle.name, port=refs[1].name, wire=j)


def _wire_index(data, block, port):
    """The index of the wire that drives ``block.port`` (None if none)."""
    dst = f"{block}.{port}"
    for j, w in enumerate(data.get("wires") or []):
        if isinstance(w, list) and len(w) == 2 and w[1] == dst:
            return j
    return None


def _signals(blocks) -> dict:
    """``{"block.port": {shape, dtype}}`` for every output port whose shape is known."""
    out = {}
    for name, b in blocks:
        for o, p in b.output_ports.items():
            if p.shape is not None:
                out[f"{name}.{o}"] = {"shape": str(tuple(p.shape)).replace(",)", ")"),
                                      "dtype": str(p.dtype)}
    return out


def check_document(data, source, out, modules=()):
    """``(errors, signals, built)`` of a scenario mapping (the module's
    docstring says how); ``built`` is ``(Diagram, simulate kwargs,
    Scenario)`` when there is no error, else None. ``out``: the folder the
    blocks may write to when run (nothing is written here)."""
    from ..scenarios.loader import Scenario
    if not data.get("blocks"):
        # an empty drawing is not an error to mark on anything, but it does not run
        return ([{"message": "the diagram has no blocks yet", "kind": "ScenarioError",
                  "block": None, "port": None, "param": None, "wire": None,
                  "cycle": None, "field": None, "refs": []}], {}, None)
    sc = Scenario(data, source, modules=tuple(modules))
    try:
        sc.validate()
    except AvError as e:
        return _fields([error_record(e)], data), {}, None
    # the loader builds it as `avblocks run` would: when that passes, the
    # run's settings are checked as the engines check them
    try:
        d, sim = sc.build(output_dir=out)
    except AvError as e:
        whole = e
    else:
        signals = _signals((n, h.block) for n, h in d.blocks.items())
        errors = check_settings(sim)
        try:        # the outcome line and figures name logged signals
            sc.hooks(d, sim)
        except AvError as e:
            rec = error_record(e)
            entry = getattr(e, "entry", None) or ""
            rec["field"] = entry.split("[")[0].split(".")[0] or None
            errors.append(rec)
        errors = _fields(errors, data)
        return errors, signals, (None if errors else (d, sim, sc))
    # it failed: piece by piece, to find every error (not only the first)
    c = _Collector(data, source, out, modules)
    c.errors.extend(check_counts(data))
    d = c.blocks()
    c.wires(d)
    drawn = {w[1] for w in data.get("wires") or []
             if isinstance(w, list) and len(w) == 2 and isinstance(w[1], str)}
    for path in d.unconnected_inputs():
        b, _, p = path.rpartition(".")
        if path in drawn:
            # a wire is drawn to it: what failed is its source block or the
            # wire itself, and that has its own error (never blame the input)
            continue
        if not any(r["block"] == b and r["port"] == p for r in c.errors):
            c.add(_unconnected(b, p), block=b, port=p)
    errors = c.errors
    ws = data.get("wires") or []
    for rec in errors:
        j = rec["wire"]
        if isinstance(j, int):
            rec["wire"] = list(ws[j]) if j < len(ws) and isinstance(ws[j], list) else None
    signals = _signals((n, h.block) for n, h in d.blocks.items())
    if not errors:             # only the whole diagram is wrong (a loop, params...)
        errors = [_whole(whole, data)]
    return _fields(errors, data), signals, None


def check_settings(sim) -> list:
    """Error records of a scenario's run settings (``simulation:``, its
    ``$references`` resolved), checked by the functions every engine checks
    its arguments with (:mod:`avblocks.core.runguard`): a finite end time
    that is a whole number of positive major steps, a known solver, a seed
    and a decimation that are whole numbers. What ``avblocks run`` would
    refuse only when it starts is shown on the field as the page draws."""
    from ..core.params import integer
    from ..core.runguard import finite_number, major_step, seed_value, whole_steps
    from ..core.solvers import make_solver
    errors = []

    def check(setting, fn):
        try:
            return fn()
        except AvError as e:
            rec = error_record(e)
            rec["param"], rec["field"] = setting, f"simulation.{setting}"
            errors.append(rec)
            return None

    t_final = check("t_final", lambda: finite_number(sim["t_final"], "t_final")
                    ) if "t_final" in sim else None
    dt = check("dt", lambda: major_step(sim["dt"])) if "dt" in sim else None
    if t_final is not None:
        check("t_final", lambda: whole_steps(0.0, t_final, 0.01 if dt is None else dt))
    if "solver" in sim:
        check("solver", lambda: make_solver(sim["solver"]))
    if "seed" in sim:
        check("seed", lambda: seed_value(sim["seed"]))
    if "log_every" in sim and sim["log_every"] is not None:
        check("log_every", lambda: integer(sim["log_every"], None, "log_every", lo=1))
    return errors


def _reference(value):
    """The diagram parameter (name without ``$``) a value is a reference to, else None."""
    from ..scenarios.loader import parameter_reference
    return parameter_reference(value)


def _references(value, message) -> list:
    """The diagram parameters an error about a document value is also
    about: the value's own ``$reference``, or, for a generator that failed
    on one argument ("in parameter 'n'"), that argument's reference. A
    value that refers to several parameters (``random_poses: {n: $agents,
    seed: $seed}``) and fails as a whole blames none of them."""
    from ..scenarios.generators import GENERATORS
    ref = _reference(value)
    if ref is not None:
        return [ref]
    if isinstance(value, dict) and len(value) == 1:
        (gen, args), = value.items()
        if gen in GENERATORS and isinstance(args, dict):
            import re
            m = re.search(r"in parameter '([A-Za-z_]\w*)'", message)
            ref = _reference(args.get(m.group(1))) if m else None
            if ref is not None:
                return [ref]
    return []


def counts(data) -> list:
    """The diagram parameters used as an agent count: a block's ``n`` or a
    generator's ``n`` given as ``$name``."""
    from ..scenarios.generators import GENERATORS
    found = []
    for spec in (data.get("blocks") or {}).values():
        if not isinstance(spec, dict):
            continue
        for k, v in spec.items():
            cands = []
            if k == "n":
                cands.append(v)
            if isinstance(v, dict) and len(v) == 1:
                (gen, args), = v.items()
                if gen in GENERATORS and isinstance(args, dict):
                    cands.append(args.get("n"))
            for c in cands:
                ref = _reference(c)
                if ref is not None and ref not in found:
                    found.append(ref)
    return found


def check_counts(data) -> list:
    """Errors of the diagram parameters used as an agent count (see
    :func:`counts`): each a whole number >= 1, as a block's ``n`` is
    (:mod:`avblocks.core.guarded`), reported on the parameter itself."""
    from ..core.params import integer
    params = data.get("parameters") or {}
    errors = []
    for name in counts(data):
        if name not in params:
            continue                        # the unknown reference has its own error
        try:
            integer(params[name], None, name, lo=1)
        except AvError as e:
            rec = error_record(e)
            head = f"in parameter '{name}': "
            if rec["message"].startswith(head):     # which count, then the library's words
                rec["message"] = f"'{name}' is an agent count: {rec['message'][len(head):]}"
            errors.append(rec)
    return errors


def _fields(errors, data) -> list:
    """Each record with ``field``, the document entry it is about
    (``blocks.drive.gain``, ``simulation.t_final``, ``parameters.agents``;
    None when it is about a port, a wire or the whole diagram) and ``refs``,
    the diagram parameters it is also about (see :func:`_references`: an
    error of ``drive.v_max: $speed`` is also ``speed``'s)."""
    def mapping(key):       # a hostile document may hold anything at any key
        v = data.get(key) if isinstance(data, dict) else None
        return v if isinstance(v, dict) else {}
    blocks, sim, params = mapping("blocks"), mapping("simulation"), mapping("parameters")
    for rec in errors:
        field, value = rec.get("field"), None
        b, p = rec.get("block"), rec.get("param")
        if field is None and b in blocks and p and isinstance(blocks[b], dict) \
                and p in blocks[b]:
            field, value = f"blocks.{b}.{p}", blocks[b][p]
        elif field is not None and field.startswith("simulation."):
            value = sim.get(field.partition(".")[2])
        elif field is None and b is None and p in params and not rec.get("port"):
            field = f"parameters.{p}"
        rec["field"] = field
        rec["refs"] = _references(value, rec["message"]) if value is not None else []
    return errors


def _unconnected(block, port):
    from ..core.errors import WiringError
    return WiringError("input is not connected", block=block, port=port,
                       hint="draw a wire to it from an output")


def _whole(e, data):
    """The error record of a whole-diagram build failure."""
    inner = e.__context__ if isinstance(e, ScenarioError) else e
    if isinstance(inner, AlgebraicLoopError):
        cycle = []
        for w in inner.cycle:
            s, _, dd = w.partition(" -> ")
            cycle += [s, dd]
        first = cycle[0].rpartition(".")[0] if cycle else None
        return error_record(e, block=first, cycle=cycle)
    rec = error_record(e)
    if isinstance(inner, AvError) and inner.block and inner.port:
        rec["block"], rec["port"] = inner.block, inner.port
        j = _wire_index(data, inner.block, inner.port)
        rec["wire"] = None if j is None else list(data["wires"][j])
    return rec


class Checker:
    """Validation with a small memory: the findings of the last
    :data:`CHECK_CACHE` scenarios, keyed by their source and their data
    (the editor's own key, the layout, is not part of it).

    Parameters
    ----------
    out_for : callable
        ``out_for(data) -> Path``: the folder a scenario's blocks may write
        to when run (nothing is written while checking).
    modules : tuple of str
        The user's block modules (``--blocks``).
    """

    def __init__(self, out_for, modules=()):
        self._out_for = out_for
        self._modules = tuple(modules)
        self._lock = threading.Lock()
        self._checked = {}

    def check(self, document, source, fresh=False):
        """``(errors, signals, built)``: the findings and, for a valid
        document, ``(Diagram, simulate kwargs, Scenario)`` (remembered for a
        few recent scenarios: ``fresh=True`` builds anew)."""
        data = copy.deepcopy(scenario_data(document))
        try:        # the same scenario as lately (a block moved, say): its findings
            key = (source, json.dumps(data, sort_keys=True, allow_nan=False))
        except (TypeError, ValueError):
            key = None
        if fresh:
            key = None
        with self._lock:
            hit = self._checked.get(key) if key is not None else None
            if hit is not None:
                self._checked[key] = self._checked.pop(key)       # most recent last
        if hit is not None:
            errors, signals, built = hit
            return copy.deepcopy(errors), copy.deepcopy(signals), built
        errors, signals, built = check_document(data, source, self._out_for(data),
                                                self._modules)
        if key is not None:
            with self._lock:
                self._checked[key] = (copy.deepcopy(errors), copy.deepcopy(signals), built)
                while len(self._checked) > CHECK_CACHE:
                    self._checked.pop(next(iter(self._checked)))
        return errors, signals, built

    def build(self, document, source, fresh=False):
        """``(Diagram, simulate kwargs, Scenario)`` of a valid document; an
        :class:`EditorError` with the errors otherwise (``fresh``: a diagram
        no one else holds)."""
        errors, _signals, built = self.check(document, source, fresh=fresh)
        if errors:
            raise EditorError("the diagram has errors", kind="InvalidDiagram",
                              errors=errors)
        return built
