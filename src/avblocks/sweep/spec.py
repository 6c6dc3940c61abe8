"""What a sweep is: a scenario, a grid of overrides, seeds, metrics.

A *case* is one point of the grid and one seed. Cases are numbered in
row-major order over ``(grid dims..., seed)`` so the number is stable
across runs and resumes (``case_id = ravel_multi_index(index, shape)``).

Override names follow ``avblocks run --set``:

- ``name`` (no dot): a scenario parameter (``agents``, ``gain``, ...);
- ``simulation.<key>``: a simulation setting (``simulation.t_final``);
- ``block.param`` (any other dotted name): a numeric block parameter, handed
  to ``simulate(params={...})`` (``drive.gain``, ``lf.k_l``).

The spec is plain JSON (stored in the Zarr store's attributes). Custom
metric functions are stored *by reference* (``"package.module:function"``),
never as code: resuming imports them by name, and a store never runs what
it holds. A function that cannot be imported by name (a lambda, one defined
in a script or a notebook) serves the run that was given it; ``resume``
then needs it again (``metrics={name: fn}``), with an error saying so;
a stored reference is imported only from ``avblocks`` or a module the
person resuming names (``modules=``).

The scenario is stored as data: a built-in by name, a YAML/TOML file by
its text (read with the scenario reader's limits) with its path and
SHA-256; a ``.py`` scenario by its path and SHA-256 only. A resume runs a
``.py`` scenario only when the person resuming names the file (a store
never chooses one) and it has that hash, and runs the bytes it checked; a
store's text is never executed.
"""

from __future__ import annotations

import hashlib
import math
import re
from pathlib import Path

import numpy as np

from ..core.errors import AvError


class SweepError(AvError):
    """A sweep is ill-formed (unknown scenario, parameter or metric, a store
    that exists or is not a sweep) or could not run."""


SPEC_VERSION = 2
#: Stores of these definition versions can be read (1: avblocks <= 0.3,
#: which kept a ``.py`` scenario's text; it is never run, see
#: :func:`avblocks.sweep.store.check_definition`).
READABLE_VERSIONS = (1, 2)
SCENARIO_KINDS = ("builtin", "yaml", "toml", "py")
_SUFFIX_KIND = {".py": "py", ".yaml": "yaml", ".yml": "yaml", ".toml": "toml"}


def sha256_of(raw: bytes) -> str:
    return hashlib.sha256(raw).hexdigest()


def _jsonable_value(v, where):
    """Grid values must survive JSON (they label the result's coordinates)."""
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, bool | int | str) or v is None:
        return v
    if isinstance(v, float):
        if not math.isfinite(v):
            raise SweepError(f"grid value {v!r} of '{where}' is not finite",
                             hint="grid values must be finite numbers or strings")
        return v
    if isinstance(v, list | tuple):
        return [_jsonable_value(x, where) for x in v]
    raise SweepError(f"grid value {v!r} of '{where}' is a {type(v).__name__}",
                     hint="grid values are numbers, strings or lists of them")


def normalise_grid(grid) -> dict:
    if grid is None:
        return {}
    if not isinstance(grid, dict):
        raise SweepError("grid must be a dict {name: [values]}",
                         found=type(grid).__name__)
    out = {}
    for k, vals in grid.items():
        if not isinstance(k, str) or not k:
            raise SweepError(f"grid names must be non-empty strings, found {k!r}")
        if k == "seed":
            raise SweepError("'seed' is not a grid name", hint="use seeds=20 or "
                             "seeds=[1, 2, 3]")
        if isinstance(vals, str | bytes) or np.ndim(vals) == 0:
            vals = [vals]
        vals = [_jsonable_value(v, k) for v in list(vals)]
        if not vals:
            raise SweepError(f"grid '{k}' has no values")
        if len({repr(v) for v in vals}) != len(vals):
            raise SweepError(f"grid '{k}' repeats a value: {vals}")
        out[k] = vals
    return out


def normalise_seeds(seeds) -> list:
    if isinstance(seeds, bool):
        raise SweepError("seeds must be a count or a list of integers", found=seeds)
    if isinstance(seeds, int | np.integer):
        if not 1 <= seeds <= 10**7:
            raise SweepError("seeds must be a count from 1 to 10^7", found=seeds)
        return list(range(int(seeds)))
    try:
        out = [int(s) for s in seeds]
    except (TypeError, ValueError):
        raise SweepError("seeds must be a count or a list of integers",
                         found=repr(seeds)) from None
    if not out or len(set(out)) != len(out):
        raise SweepError("seeds must be a non-empty list of distinct integers",
                         found=out)
    return out


def scenario_source(scenario) -> dict:
    """How a sweep names its scenario, as stored (plain data, no code).

    - a built-in: ``{"name", "kind": "builtin"}``;
    - a YAML/TOML file: ``{"name", "kind", "path", "sha256", "text"}``
      (the text is data: a remote worker and a later resume need no copy);
    - a ``.py`` file: ``{"name", "kind": "py", "path", "sha256"}`` and, in
      this process only, ``"_text"``: the bytes read now, which the tasks
      carry to the workers; never stored (keys starting with ``_`` are not).

    The file is read once (a regular file within the scenario size limit)
    and its path made absolute, so a resume from another folder finds it.
    """
    from ..scenarios import builtin_scenarios
    from ..scenarios.files import read_bytes
    p = Path(str(scenario))
    builtin = builtin_scenarios()
    if not p.is_file() and str(scenario) in builtin:
        return {"name": str(scenario), "kind": "builtin"}
    if not p.exists():
        raise SweepError(f"no built-in scenario or file named '{scenario}'",
                         hint=f"built-in scenarios: {sorted(builtin)}")
    kind = _SUFFIX_KIND.get(p.suffix)
    if kind is None:
        raise SweepError(f"unknown scenario file type '{p.suffix}'",
                         hint="use a .yaml, .yml, .toml or .py scenario")
    raw = read_bytes(p)
    text = _decoded(raw, p)
    src = {"name": p.stem, "kind": kind, "path": str(p.resolve()), "sha256": sha256_of(raw)}
    if kind == "py":
        src["_text"] = text
    else:
        src["text"] = text
        src["_folder"] = str(p.resolve().parent)      # the file's own, as `avblocks run`
    return src


def _decoded(raw, path):
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise SweepError(f"{path}: not UTF-8 text (byte 0x{raw[e.start]:02x} at offset "
                         f"{e.start})") from None


def checked_python(src) -> dict:
    """``src`` (a ``.py`` scenario as stored) with ``_text``: the file at its
    path, read once, when it has the stored SHA-256; a :class:`SweepError`
    naming the file and both hashes otherwise (the store's definition
    never carries code to run)."""
    from ..core.errors import ScenarioError
    from ..scenarios.files import read_bytes
    if "_text" in src:
        return src
    path = src["path"]
    try:
        raw = read_bytes(Path(path))
    except ScenarioError as e:
        raise SweepError(f"the sweep's Python scenario cannot be read: {e}",
                         hint="a sweep store keeps no code: put the scenario file back at "
                              f"'{path}' (the same content) to resume") from None
    got = sha256_of(raw)
    if got != src["sha256"] and src.get("text_newlines"):
        # a store of avblocks <= 0.3 hashed here from the text it kept, read
        # with universal newlines: compare the file read the same way
        try:
            same = raw.decode("utf-8").replace("\r\n", "\n").replace("\r", "\n")
            got = sha256_of(same.encode("utf-8"))
        except UnicodeDecodeError:
            pass
    if got != src["sha256"]:
        raise SweepError(f"the sweep's Python scenario '{path}' changed since the sweep "
                         f"started: its SHA-256 is {got}, the store expects "
                         f"{src['sha256']}",
                         hint="restore that version of the file, or start a new sweep "
                              "(another out=) with the file as it is now")
    return {**src, "_text": _decoded(raw, path)}


def _stored_folder(src):
    """The folder a stored YAML/TOML scenario may read files from: its own
    file's folder when the file at the stored path still has the stored
    hash (the person resuming has that very file), else none."""
    from ..core.errors import ScenarioError
    from ..scenarios.files import read_bytes
    try:
        same = sha256_of(read_bytes(Path(src["path"]))) == src.get("sha256")
    except (ScenarioError, OSError, KeyError, TypeError):
        same = False
    return str(Path(src["path"]).parent) if same else None


def scenario_of(src):
    """The scenario (not yet overridden) a :func:`scenario_source` names:
    the one path of :mod:`avblocks.scenarios.targets`. A built-in only by
    a name of :func:`~avblocks.scenarios.builtin_scenarios`; a ``.py``
    scenario from the text this process checked (``_text``), never from a
    store; a YAML/TOML scenario from its text, read with the scenario
    reader's limits."""
    import importlib

    from ..scenarios import Scenario, builtin_scenarios, load_scenario
    from ..scenarios.targets import PythonScenario, run_python_file
    kind = src.get("kind")
    if kind == "builtin":
        b = builtin_scenarios()
        name = src.get("name")
        if name not in b:
            raise SweepError(f"no built-in scenario named {str(name)!r:.80}",
                             hint=f"built-in scenarios: {sorted(b)}")
        if b[name].suffix == ".py":
            mod = importlib.import_module(f"avblocks.scenarios.{name}")
            return PythonScenario(vars(mod), name, name)
        return load_scenario(b[name])
    if kind == "py":
        src = checked_python(src)
        return run_python_file(src["path"], src["_text"])
    if kind not in ("yaml", "toml"):
        raise SweepError(f"unknown scenario kind {str(kind)!r:.40}",
                         hint=f"kinds: {list(SCENARIO_KINDS)}")
    from ..scenarios.files import parse_text
    source = src.get("path") or f"<{src.get('name')}.{kind}>"
    folder = src["_folder"] if "_folder" in src else _stored_folder(src)
    data = parse_text(src["text"], source, "." + kind)
    sc = Scenario(data if data is not None else {}, source, read_folder=folder or "")
    sc.validate()
    return sc


def split_overrides(values: dict):
    """``(scenario overrides, block parameters)`` from override names
    (:func:`avblocks.scenarios._numeric.split_overrides`)."""
    from ..scenarios.targets import split_overrides as split
    return split(values)


def build_case(src, values: dict, seed: int):
    """``(diagram, simulate kwargs)`` of one case: the scenario with its
    overrides; the seed goes to the scenario's ``seed`` parameter when it
    has one and to ``simulate(seed=)`` always; block parameters go to
    ``simulate(params=)`` (checked against the built diagram)."""
    sc = scenario_of(src)
    if sc.accepts("seed"):
        values = {**values, "seed": int(seed)}
    d, sim = sc.with_overrides(values).build()
    sim = dict(sim)
    sim["seed"] = int(seed)
    return d, sim


_METRIC_REF = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*"
                         r":[A-Za-z][A-Za-z0-9_]*(\.[A-Za-z][A-Za-z0-9_]*)*$")


def metric_reference(fn) -> str | None:
    """``"module:qualname"`` when importing that name gives ``fn`` back
    (then a resumed sweep finds it again), else None."""
    mod, qual = getattr(fn, "__module__", None), getattr(fn, "__qualname__", None)
    if not mod or not qual or mod == "__main__" or "<" in qual:
        return None
    try:
        return f"{mod}:{qual}" if resolve_metric(f"{mod}:{qual}", "?", (mod,)) is fn \
            else None
    except SweepError:
        return None


def resolve_metric(ref: str, name: str, modules=()):
    """The function named by ``ref`` (``"package.module:function"``),
    imported by name from ``avblocks`` or one of ``modules`` (and the
    modules below them) only; a :class:`SweepError` naming the metric
    otherwise. The name is public (no part starts with ``_``) and must
    give a plain Python function."""
    import importlib
    import inspect
    if not isinstance(ref, str) or not _METRIC_REF.match(ref):
        raise SweepError(f"metric '{name}' refers to {str(ref)!r:.80}, which is not "
                         "'package.module:function'")
    mod, _, qual = ref.partition(":")
    allowed = ("avblocks", *[str(m) for m in modules or ()])
    if not any(mod == a or mod.startswith(a + ".") for a in allowed):
        raise SweepError(f"metric '{name}' refers to {ref!r}, in a module this resume "
                         "may not import",
                         hint=f"name the module: resume(..., modules=['{mod}']) (CLI: "
                              f"--metrics-module {mod}), or hand the function: "
                              f"resume(..., metrics={{'{name}': fn}})")
    def inside(module_name):
        return any(module_name == a or module_name.startswith(a + ".") for a in allowed)

    try:
        obj = importlib.import_module(mod)
        for part in qual.split("."):
            obj = getattr(obj, part)
            if inspect.ismodule(obj) and not inside(obj.__name__):
                raise SweepError(f"metric '{name}' refers to {ref!r}, which goes through "
                                 f"the module '{obj.__name__}', not one this resume may "
                                 "import")
    except SweepError:
        raise
    except Exception as e:  # noqa: BLE001 - any import failure is the same answer
        raise SweepError(f"metric '{name}' refers to {ref!r}, which cannot be imported "
                         f"({type(e).__name__}: {e})",
                         hint="install or put on sys.path the package that defines it, or "
                              "resume with metrics={name: fn}") from None
    if not inspect.isfunction(obj):
        raise SweepError(f"metric '{name}' refers to {ref!r}, which is not a Python "
                         "function")
    home = getattr(obj, "__module__", None) or ""
    if not inside(home):
        # a name another module imported (avblocks.core.confined:shutil.rmtree)
        raise SweepError(f"metric '{name}' refers to {ref!r}, a function of '{home}', "
                         "not of a module this resume may import",
                         hint=f"name the module: --metrics-module {home}")
    return obj


class Spec:
    """A sweep's definition; cheap to ship to workers."""

    def __init__(self, data: dict):
        self.data = data
        self.grid = data["grid"]
        self.seeds = data["seeds"]
        self.dims = list(self.grid) + ["seed"]
        self.shape = tuple(len(v) for v in self.grid.values()) + (len(self.seeds),)
        self.n_cases = int(np.prod(self.shape))
        self._metric_fns = None

    def case(self, case_id: int):
        """``(values {grid name: value}, seed)`` of case ``case_id``."""
        idx = np.unravel_index(int(case_id), self.shape)
        values = {k: v[i] for (k, v), i in zip(self.grid.items(), idx[:-1])}
        return {**self.data["fixed"], **values}, self.seeds[idx[-1]]

    def label(self, case_id: int) -> str:
        values, seed = self.case(case_id)
        grid = {k: values[k] for k in self.grid}
        return ", ".join(f"{k}={v}" for k, v in {**grid, "seed": seed}.items())

    def metric_fns(self) -> dict:
        """``{name: fn}``: functions handed to this process (``_callables``,
        never stored), else imported by their stored reference, else the
        built-in metric of that name."""
        if self._metric_fns is None:
            from .metrics import METRICS
            given = self.data.get("_callables") or {}
            refs = self.data.get("metric_refs") or {}
            modules = self.data.get("_modules") or ()
            fns = {}
            for n in self.data["metrics"]:
                if n in given:
                    fns[n] = given[n]
                elif refs.get(n):
                    fns[n] = resolve_metric(refs[n], n, modules)
                elif n in refs or n not in METRICS:
                    raise SweepError(
                        f"metric '{n}' was a function that cannot be imported by name "
                        "(a lambda, or defined in a script); a sweep store keeps no code",
                        hint=f"resume with metrics={{'{n}': fn}}, or define the function "
                             "in an importable module")
                else:
                    fns[n] = METRICS[n]
            self._metric_fns = fns
        return self._metric_fns

    def build(self, case_id: int):
        values, seed = self.case(case_id)
        return build_case(self.data["scenario"], values, seed)


_SPEC_CACHE: dict = {}


def cached_spec(spec_data) -> Spec:
    """The :class:`Spec` of ``spec_data``, built once per worker process and
    run (the last one is kept: a worker runs the cases of one sweep at a
    time; a resume is another run, whose metric functions may differ)."""
    key = (spec_data["token"], spec_data.get("_run"))
    sp = _SPEC_CACHE.get(key)
    if sp is None:
        _SPEC_CACHE.clear()
        sp = _SPEC_CACHE[key] = Spec(spec_data)
    return sp
