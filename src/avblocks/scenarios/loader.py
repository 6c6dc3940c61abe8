"""Scenario files: a diagram declared as data (YAML or TOML), never code.

A scenario file has five sections::

    name: waypoints
    description: N unicycles drive through random waypoints.
    parameters:            # the knobs; change with `--set agents=300`
      agents: 15
      seed: 1
    blocks:                # name -> {type: <family.Class>, <param>: <value>}
      fleet:
        type: vehicles.Unicycle
        pose0: {random_poses: {n: $agents, area: [50, 50], seed: $seed}}
      drive:
        type: controllers.PointToPoint
        waypoints: {random_waypoints: {n: $agents, count: 3, area: [50, 50], seed: $seed}}
    wires:                 # [source output, destination input]
      - [fleet.pose, drive.pose]
      - [drive.cmd, fleet.cmd]
    simulation: {t_final: 60, dt: 0.01, solver: rk4, log: [fleet.pose], seed: $seed}
    params: {drive.gain: 2.0}   # optional: numeric block parameters (block.param)
    movie: {trail: 5.0}    # optional: options for `avblocks run ... --movie`
    outcome: [{metric: all_true, signal: drive.done, what: done}]   # optional
    figures: [{plot: trajectories, file: paths.png, waypoints: drive}]  # optional

(``outcome`` and ``figures`` name built-in metrics and plots, see
:mod:`avblocks.scenarios.report`.)

Values may be plain numbers, lists, strings, ``$parameter`` references
(also inside strings: ``"${agents}"``), a one-key mapping naming one of
the generators in :data:`GENERATORS`, a ``{world: {...}}`` or a
``{mujoco_scene: {...}}`` (:mod:`avblocks.scenarios.scenes`), or
``{function: "module:name"}``: a
function of the library (a module under ``avblocks``) or of a block module
the user named (``--blocks``), by importable name, e.g. the ``fn`` of a
``blocks.Function`` (see :func:`resolve_function`). Nothing in the file is
executed.

``params`` sets numeric parameters of the built blocks by dotted path (see
:mod:`avblocks.scenarios._numeric`); ``--set drive.gain=3`` overrides them.
"""

from __future__ import annotations

import inspect
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

from ..core.diagram import Diagram
from ..core.errors import AvError, ScenarioError, did_you_mean
from ._numeric import resolve, split_overrides
from .files import _read
from .generators import GENERATORS
from .limits import (  # noqa: F401  (as before)
    MAX_DEPTH,
    MAX_FILE_BYTES,
    MAX_WIRES,
    MAX_YAML_VALUES,
    check_values,
    max_blocks,
    memory_limit,
    too_many_blocks,
)
from .report import REPORTS  # noqa: F401  (loader.REPORTS, as before)
from .worlds import _parse_world

#: a ``$parameter`` (or ``${parameter}``) reference: a whole text value
PARAM_REF = _REF = re.compile(r"^\$\{?([A-Za-z_][A-Za-z0-9_]*)\}?$")
_SECTIONS = {"name", "description", "parameters", "blocks", "wires", "simulation",
             "movie", "params", "outcome", "figures", "report", "editor"}
_SIM_KEYS = {"t_final", "dt", "solver", "log", "log_every", "seed", "realtime"}
#: ``--set`` names that go to the simulation settings when the scenario has
#: no parameter of that name (the same names as the Python scenarios').
_SIM_SHORTCUTS = {"t_final", "dt", "log_every", "solver"}
#: Block arguments (and movie options) naming files a scenario writes: they
#: must stay inside the output folder.
WRITE_KEYS = {"path", "movie", "file", "filename", "output", "save", "save_path"}
#: ... and files it reads: they must lie under the scenario file's folder.
READ_KEYS = {"background", "image", "map", "geojson"}
#: ... and a trained policy's file (``tasks.TaskCommand``'s ``policy``):
#: under the folder too, unless the person running named it on the
#: command line (``--set controller=policy.npz``: theirs, like ``--out``);
#: ``NO_POLICY`` values name no file.
POLICY_KEYS = {"policy"}
NO_POLICY = {"", "scripted"}      # tasks.TaskCommand.SCRIPTED


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def parameter_reference(value):
    """The diagram parameter a value refers to (``"$agents"`` or
    ``"${agents}"``: ``"agents"``), else None."""
    m = _REF.match(value.strip()) if isinstance(value, str) else None
    return m.group(1) if m else None


def check_editor(section, source="<scenario>"):
    """The ``editor:`` section (the block-diagram editor's layout): checked
    lightly, never used to build or run. ``layout`` maps block names to
    ``[x, y]``; ``groups`` maps group names to ``{blocks: [names...],
    position: [x, y], label: str, groups: [...]}``; ``viewport`` is
    ``[x, y, zoom]``. Other keys are kept and ignored. A malformed section
    is a :class:`ScenarioError` naming the entry."""
    if section is None:
        return
    if not isinstance(section, dict):
        raise ScenarioError("'editor' must be a mapping (layout, groups, viewport)",
                            file=source, entry="editor")

    def point(v, where, n=2):
        if not (isinstance(v, list) and len(v) == n and all(_is_number(x) for x in v)):
            raise ScenarioError(f"expected a list of {n} numbers, found {v!r:.60}",
                                file=source, entry=where)

    layout = section.get("layout")
    if layout is not None:
        if not isinstance(layout, dict):
            raise ScenarioError("'editor.layout' must map block names to [x, y]",
                                file=source, entry="editor.layout")
        for k, v in layout.items():
            point(v, f"editor.layout.{k}")
    groups = section.get("groups")
    if groups is not None:
        if not isinstance(groups, dict):
            raise ScenarioError("'editor.groups' must map group names to "
                                "{blocks: [...], position: [x, y]}", file=source,
                                entry="editor.groups")
        for k, g in groups.items():
            where = f"editor.groups.{k}"
            if not isinstance(g, dict):
                raise ScenarioError("a group is a mapping {blocks: [...], position: [x, y]}",
                                    file=source, entry=where)
            blocks = g.get("blocks", [])
            if not (isinstance(blocks, list) and all(isinstance(b, str) for b in blocks)):
                raise ScenarioError("'blocks' must be a list of block names",
                                    file=source, entry=f"{where}.blocks")
            if g.get("position") is not None:
                point(g["position"], f"{where}.position")
            if g.get("label") is not None and not isinstance(g["label"], str):
                raise ScenarioError("'label' must be text", file=source,
                                    entry=f"{where}.label")
            sub = g.get("groups", [])
            if not (isinstance(sub, list) and all(isinstance(b, str) for b in sub)):
                raise ScenarioError("'groups' must be a list of group names",
                                    file=source, entry=f"{where}.groups")
    if section.get("viewport") is not None:
        point(section["viewport"], "editor.viewport", 3)


FUNCTION_REF = _FUNCTION_REF = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*(?:\.[A-Za-z_][A-Za-z0-9_]*)*)"
                           r":([A-Za-z][A-Za-z0-9_]*)$")


def resolve_function(ref, modules=(), source="<scenario>", where="function"):
    """The function a file names as ``"package.module:name"``.

    Only modules of the library (``avblocks`` and below) and the user's
    block modules (``modules``, named on the command line, and below) are
    imported; the name must be public (no leading underscore) and a plain
    Python function (not a class, so nothing is constructed) defined in
    one of those modules (not one they imported from elsewhere). Anything
    else is a :class:`ScenarioError` naming the entry."""
    import importlib
    if not isinstance(ref, str) or not _FUNCTION_REF.match(ref):
        raise ScenarioError(f"expected 'package.module:function', found {ref!r:.80}",
                            file=source, entry=where,
                            hint="e.g. avblocks.scenarios.honeybee:choose_command")
    mod_name, name = ref.split(":")
    allowed = ("avblocks", *[str(m) for m in modules or ()])
    if not any(mod_name == a or mod_name.startswith(a + ".") for a in allowed):
        raise ScenarioError(f"'{mod_name}' is not a module a file may name",
                            file=source, entry=where,
                            hint="functions come from avblocks or a block module "
                                 "given with --blocks")
    try:
        mod = importlib.import_module(mod_name)
    except ImportError as e:
        raise ScenarioError(f"cannot import '{mod_name}': {e}", file=source,
                            entry=where) from None
    fn = getattr(mod, name, None)
    if not inspect.isfunction(fn):
        raise ScenarioError(f"'{ref}' is not a function", file=source, entry=where,
                            hint=did_you_mean(name, [n for n in dir(mod)
                                                     if inspect.isfunction(getattr(mod, n))
                                                     and not n.startswith("_")]))
    home = getattr(fn, "__module__", None) or ""
    if not any(home == a or home.startswith(a + ".") for a in allowed):
        # a name the module imported from elsewhere (dataclasses.dataclass)
        raise ScenarioError(f"'{ref}' is a function of '{home}', not of a module a file "
                            "may name", file=source, entry=where,
                            hint="functions come from avblocks or a block module "
                                 "given with --blocks")
    return fn


# ------------------------------------------------------------------ registry
def module_blocks(module) -> dict:
    """``{"module.Class": class}`` of the public block classes a user's
    module defines (its ``__all__``, else its public names): the blocks of
    ``avblocks edit --blocks mypackage.blocks``. Importing the module runs
    it: it is named by the user on the command line, never by a file."""
    import importlib

    try:
        mod = importlib.import_module(str(module))
    except ImportError as e:
        raise ScenarioError(f"cannot import the block module '{module}': {e}",
                            entry="--blocks") from None
    out = {}
    for name in getattr(mod, "__all__", [n for n in dir(mod) if not n.startswith("_")]):
        obj = getattr(mod, name, None)
        if is_block_class(obj):
            out[f"{module}.{name}"] = obj
    return out


def is_block_class(obj) -> bool:
    """Whether ``obj`` is a class a file can name as a block: a
    :class:`~avblocks.core.block.Block` subclass, or a
    :class:`~avblocks.core.diagram.Diagram` subclass (a subsystem such as
    ``vehicles.VelocityControlledQuadrotor``)."""
    from ..core.block import Block
    return (inspect.isclass(obj) and issubclass(obj, (Block, Diagram))
            and obj not in (Block, Diagram))


#: Interface packages whose blocks a scenario file may name
#: (``interfaces.mujoco.PhysicsWorld``): physics and cameras, which talk to
#: nothing outside the process. Robots and drones are reached with
#: ``avblocks run ... --robots``, never from a file.
FILE_INTERFACES = ("mujoco", "vision")


def block_registry(code_blocks=False, modules=(), interfaces=False) -> dict:
    """``{"vehicles.Unicycle": class, ...}`` for every public block class
    that a scenario file can name (``code_blocks=True``: also those that
    take Python code, such as ``blocks.Function``; ``interfaces=True``:
    also the blocks of :data:`FILE_INTERFACES`, named
    ``"interfaces.mujoco.SceneCamera"``, which need their extras;
    ``modules``: user modules whose blocks
    are named ``"module.Class"``, see :func:`module_blocks`)."""
    import importlib

    reg = {}
    for fam in ("blocks", "vehicles", "controllers", "environment", "tasks", "viz"):
        try:
            mod = importlib.import_module(f"avblocks.{fam}")
        except ImportError:  # optional family whose extra is missing
            continue
        for name in getattr(mod, "__all__", dir(mod)):
            obj = getattr(mod, name, None)
            if is_block_class(obj):
                if name == "Function" and not code_blocks:   # takes Python code
                    continue
                reg[f"{fam}.{name}"] = obj
    for fam in FILE_INTERFACES if interfaces else ():
        mod = importlib.import_module(f"avblocks.interfaces.{fam}")  # extras load lazily
        for name in mod.__all__:
            obj = getattr(mod, name, None)
            if is_block_class(obj):
                reg[f"interfaces.{fam}.{name}"] = obj
    for m in modules or ():
        reg.update(module_blocks(m))
    return reg


def _no_folder() -> Path:
    """An empty folder of this process that nothing is ever written to: the
    folder of a scenario that may read no file (every name it gives is
    outside it or not a file in it)."""
    global _EMPTY
    if _EMPTY is None or not _EMPTY.is_dir():
        import atexit
        import tempfile
        _EMPTY = Path(tempfile.mkdtemp(prefix="avblocks-no-files-"))
        _EMPTY.chmod(0o500)
        atexit.register(_remove_quietly, _EMPTY)
    return _EMPTY


def _remove_quietly(folder):
    import contextlib
    with contextlib.suppress(OSError):
        folder.rmdir()


_EMPTY = None


@dataclass
class Scenario:
    """A parsed scenario: its data, with parameters substituted on build."""

    data: dict
    source: str = "<dict>"
    params: dict = field(default_factory=dict)
    #: user block modules whose blocks the file may name (``module.Class``)
    modules: tuple = ()
    #: text values the person running gave on the command line
    #: (``with_overrides(..., user=True)``): a policy path among them is
    #: theirs to name, anywhere; a policy path the file names is confined
    user_values: frozenset = frozenset()
    #: the folder the scenario may read files from when it is not the
    #: source file's own (a sweep store's scenario: its file's folder when
    #: that file is unchanged); ``""``: no folder, every file it names is
    #: refused
    read_folder: str | None = None

    @property
    def name(self) -> str:
        return str(self.data.get("name", Path(self.source).stem))

    @property
    def folder(self) -> Path:
        """The folder a scenario file may read from (its own)."""
        if self.read_folder is not None:
            return Path(self.read_folder) if self.read_folder else _no_folder()
        if self.source.startswith("<"):
            return Path.cwd()
        return Path(self.source).resolve().parent

    @property
    def description(self) -> str:
        return str(self.data.get("description", ""))

    # ----------------------------------------------------------- values
    def value(self, v, where="value", params=None):
        """A file value (``$parameter`` references, generators) resolved with
        this scenario's parameters (``params`` on top), as :meth:`build`
        resolves a block argument."""
        self.params = {**dict(self.data.get("parameters") or {}), **dict(params or {})}
        self._generated_bytes = 0
        return self._value(v, where)

    def _value(self, v, where):
        if isinstance(v, str):
            m = _REF.match(v.strip())
            if m:
                key = m.group(1)
                if key not in self.params:
                    raise ScenarioError(f"unknown parameter reference '${key}'",
                                        file=self.source, entry=where,
                                        hint=did_you_mean(key, self.params)
                                        + f"known parameters: {sorted(self.params)}")
                return self.params[key]
            return v
        if isinstance(v, list):
            return [self._value(x, f"{where}[{i}]") for i, x in enumerate(v)]
        if isinstance(v, dict):
            if len(v) == 1:
                (k, args), = v.items()
                if k in GENERATORS:
                    args = self._value(args, f"{where}.{k}")
                    if not isinstance(args, dict):
                        raise ScenarioError(f"generator '{k}' takes a mapping of "
                                            "arguments", file=self.source, entry=where)
                    sig = inspect.signature(GENERATORS[k])
                    try:
                        sig.bind(**args)
                    except TypeError as e:
                        raise ScenarioError(f"bad arguments for '{k}': {e}",
                                            file=self.source, entry=where,
                                            hint=f"'{k}' takes {sig}") from None
                    try:
                        return self._count(GENERATORS[k](**args), k, where)
                    except ScenarioError:
                        raise
                    except MemoryError:
                        raise ScenarioError(f"'{k}' ran out of memory", file=self.source,
                                            entry=where, hint="use fewer agents/points"
                                            ) from None
                    except (AvError, RecursionError) as e:
                        raise ScenarioError(f"'{k}' failed: {e}", file=self.source,
                                            entry=where, hint=f"'{k}' takes {sig}"
                                            ) from None
                    except Exception as e:  # noqa: BLE001 - a generator's own failure
                        raise ScenarioError(f"'{k}' failed: {type(e).__name__}: {e}",
                                            file=self.source, entry=where,
                                            hint=f"'{k}' takes {sig}") from None
                if k == "function":
                    return resolve_function(self._value(args, f"{where}.function"),
                                            self.modules, self.source, where)
                if k == "world":
                    return _parse_world(self._value(args, f"{where}.world"),
                                        where, self.folder, self.source)
                if k == "mujoco_scene":
                    from .scenes import mujoco_scene
                    return mujoco_scene(self._value(args, f"{where}.mujoco_scene"),
                                        f"{where}.mujoco_scene", self.folder, self.source)
            return {k: self._value(x, f"{where}.{k}") for k, x in v.items()}
        return v

    def _count(self, value, generator, where):
        """``value``, after adding its size to what this build generated so
        far: past the memory limit in all (many blocks times many agents,
        each array within the limit) the build stops here."""
        total = getattr(self, "_generated_bytes", 0) + int(getattr(value, "nbytes", 0))
        self._generated_bytes = total
        lim = memory_limit()
        if total > lim:
            raise ScenarioError(f"the generated values take {total / 1e9:.3g} GB in all "
                                f"(more than {lim / 1e9:.3g} GB) after '{generator}'",
                                file=self.source, entry=where,
                                hint="use fewer agents or blocks (AVBLOCKS_MAX_MEMORY)")
        return value

    def accepts(self, key) -> bool:
        """Whether ``key`` is one of this scenario's parameters."""
        return key in (self.data.get("parameters") or {})

    def with_overrides(self, overrides: dict, *, user=False) -> Scenario:
        """A copy with ``--set`` values applied: parameter names,
        ``simulation.<key>``, the shortcuts ``t_final``/``dt``/``log_every``/
        ``solver``, or ``block.param`` (checked against the built diagram by
        :meth:`build`). The copy is validated when it is built.

        ``user``: the values come from the person running (``avblocks run
        --set``), not from a file: a policy path among them
        (``--set controller=policy.npz``) is read where they say, as
        ``--out`` is; one from a file (a sweep's values included) must lie
        under the scenario file's folder."""
        import copy
        if not isinstance(self.data, dict) or not isinstance(
                self.data.get("parameters") or {}, dict):
            self.validate()                 # raises, naming what is wrong
        self._check_values()                # before deepcopy walks it
        check_values(dict(overrides or {}), self.source)
        data = copy.deepcopy(self.data)
        params = dict(data.get("parameters") or {})
        plain, numeric = split_overrides(overrides)
        if numeric:                         # block.param: checked on build
            data["params"] = {**(data.get("params") or {}), **numeric}
        for key, val in plain.items():
            if key.startswith("simulation."):
                sub = key.split(".", 1)[1]
                if sub not in _SIM_KEYS:
                    raise ScenarioError(f"unknown simulation setting '{sub}'",
                                        file=self.source, entry=f"--set {key}",
                                        hint=did_you_mean(sub, _SIM_KEYS)
                                        + f"known: {sorted(_SIM_KEYS)}")
                data["simulation"] = {**(data.get("simulation") or {}), sub: val}
            elif key in params:
                params[key] = val
            elif key in _SIM_SHORTCUTS:     # --set t_final=30 as in Python scenarios
                data["simulation"] = {**(data.get("simulation") or {}), key: val}
            else:
                raise ScenarioError(f"unknown parameter '{key}'", file=self.source,
                                    entry=f"--set {key}",
                                    hint=did_you_mean(key, params)
                                    + f"this scenario's parameters: {sorted(params)} "
                                      "(or t_final, dt, log_every, simulation.<setting>, "
                                      "block.param)")
        data["parameters"] = params
        mine = frozenset(str(v) for v in plain.values() if isinstance(v, str)) if user \
            else frozenset()
        return Scenario(data, self.source, modules=self.modules,
                        user_values=self.user_values | mine, read_folder=self.read_folder)

    def hooks(self, diagram, sim):
        """The ``outcome``/``figures`` of this scenario built as ``diagram``
        with simulate kwargs ``sim`` (:mod:`avblocks.scenarios.report`):
        its own sections, else those of the case study its ``report:`` names."""
        from ._report_schema import logged_signals
        from .report import hooks_from_data, hooks_from_report
        d = self.data
        hooks = hooks_from_data(d.get("outcome"), d.get("figures"), diagram, self.source,
                                log=sim.get("log"))
        if d.get("report"):
            hooks = hooks_from_report(d["report"], d.get("parameters") or {}, hooks,
                                      logged_signals(diagram, sim.get("log"), self.source),
                                      self.source)
        return hooks

    def movie(self) -> dict:
        """The movie options, values resolved (after :meth:`build`)."""
        return self._value(self.movie_options(), "movie")       # generators too

    # ------------------------------------------------------------- build
    def _check_values(self):
        """The data within the limits of :func:`~avblocks.scenarios.limits.check_values`
        (nesting, sizes): checked before anything recursive walks it."""
        check_values(self.data, self.source)

    def validate(self):
        d = self.data
        if not isinstance(d, dict):
            raise ScenarioError("a scenario must be a mapping with sections "
                                f"{sorted(_SECTIONS)}", file=self.source)
        self._check_values()
        unknown = set(d) - _SECTIONS
        if unknown:
            raise ScenarioError(f"unknown section(s) {sorted(unknown)}", file=self.source,
                                hint=f"sections are {sorted(_SECTIONS)}")
        if not isinstance(d.get("movie") or {}, dict):
            raise ScenarioError("'movie' must be a mapping of movie options",
                                file=self.source, entry="movie")
        rep = d.get("report")
        if rep is not None and (not isinstance(rep, str) or rep not in REPORTS):
            shown = rep if isinstance(rep, str) else repr(rep)[:60]
            raise ScenarioError(f"unknown report '{shown}'", file=self.source,
                                entry="report",
                                hint=did_you_mean(shown, REPORTS)
                                + f"reports: {list(REPORTS)}")
        check_editor(d.get("editor"), self.source)
        from ._report_schema import check_sections
        check_sections(d.get("outcome"), d.get("figures"), self.source)
        if not isinstance(d.get("blocks"), dict) or not d["blocks"]:
            raise ScenarioError("'blocks' must map block names to their settings",
                                file=self.source, entry="blocks")
        if len(d["blocks"]) > max_blocks():
            raise too_many_blocks(len(d["blocks"]), self.source)
        params = d.get("parameters") or {}
        if not isinstance(params, dict):
            raise ScenarioError("'parameters' must be a mapping", file=self.source,
                                entry="parameters")
        wires = d.get("wires") or []
        if not isinstance(wires, list):
            raise ScenarioError("'wires' must be a list of [source, destination]",
                                file=self.source, entry="wires")
        if len(wires) > MAX_WIRES:
            raise ScenarioError(f"{len(wires):,} wires, more than {MAX_WIRES:,}",
                                file=self.source, entry="wires")
        sim = d.get("simulation") or {}
        if not isinstance(sim, dict):
            raise ScenarioError("'simulation' must be a mapping", file=self.source,
                                entry="simulation")
        if not isinstance(d.get("params") or {}, dict):
            raise ScenarioError("'params' must map 'block.param' to values",
                                file=self.source, entry="params")
        bad = set(sim) - _SIM_KEYS
        if bad:
            raise ScenarioError(f"unknown simulation setting(s) {sorted(bad)}",
                                file=self.source, entry="simulation",
                                hint=f"known: {sorted(_SIM_KEYS)}")

    def output_dir(self, output_dir=None) -> Path:
        """Where this scenario's files go: ``output_dir`` or
        ``avblocks-out/<name>`` (the name made safe as one folder name)."""
        from .paths import safe_name
        if output_dir is not None:
            return Path(output_dir)
        return Path("avblocks-out") / safe_name(self.name)

    def _confine(self, kwargs, where, out):
        """Paths a file names: writes only inside ``out``, reads only under
        the scenario's own folder."""
        from .paths import inside
        for k, v in kwargs.items():
            if not isinstance(v, (str, Path)):
                continue
            if k in WRITE_KEYS:
                kwargs[k] = inside(v, out, what=f"{where}.{k}", source=self.source)
            elif k in READ_KEYS:
                kwargs[k] = inside(v, self.folder, what=f"{where}.{k}", source=self.source,
                                   must_exist=True)
            elif k in POLICY_KEYS and str(v) not in NO_POLICY \
                    and str(v) not in self.user_values:
                kwargs[k] = str(inside(v, self.folder, what=f"{where}.{k}",
                                       source=self.source, must_exist=True))
        return kwargs

    def movie_options(self) -> dict:
        """The ``movie:`` section, its file names confined to the scenario's folder."""
        opts = dict(self.data.get("movie") or {})
        return self._confine(opts, "movie", self.folder)

    def build(self, output_dir=None):
        """The :class:`Diagram` and the keyword arguments for ``simulate``.

        ``output_dir`` is the only folder the scenario's blocks may write to
        (a Scope's ``path``, an animation's ``movie``: relative names land
        in it, names leaving it are refused); default ``avblocks-out/<name>``.
        Files a scenario reads (backgrounds, map images) must lie under the
        scenario file's own folder."""
        try:
            return self._build(self.output_dir(output_dir))
        except RecursionError:
            raise ScenarioError("the file nests values too deeply", file=self.source
                                ) from None

    def _build(self, out):
        self.validate()
        self.params = dict(self.data.get("parameters") or {})
        self._generated_bytes = 0
        # a file may name blocks.Function: its fn can only be a function
        # resolved by name ({function: "module:name"}), never code
        reg = block_registry(code_blocks=True, modules=self.modules, interfaces=True)
        d = Diagram(self.name)
        for name, spec in self.data["blocks"].items():
            where = f"blocks.{name}"
            if not isinstance(spec, dict) or "type" not in spec:
                raise ScenarioError("each block needs a 'type'", file=self.source,
                                    entry=where, hint="e.g. type: vehicles.Unicycle")
            typ = spec["type"]
            if not isinstance(typ, str):
                raise ScenarioError("'type' must be a block type name",
                                    file=self.source, entry=f"{where}.type",
                                    hint=f"e.g. vehicles.Unicycle, found {typ!r:.60}")
            if typ not in reg:
                import difflib
                close = difflib.get_close_matches(str(typ), list(reg), n=1, cutoff=0.6)
                raise ScenarioError(f"unknown block type '{typ}'", file=self.source,
                                    entry=f"{where}.type",
                                    hint=(f"did you mean '{close[0]}'?" if close else
                                          "run `avblocks list --blocks` for the types"))
            cls = reg[typ]
            kwargs = {k: self._value(v, f"{where}.{k}") for k, v in spec.items()
                      if k != "type"}
            sig = inspect.signature(cls.__init__)
            accepted = [p for p in sig.parameters if p != "self"]
            has_var = any(p.kind == p.VAR_KEYWORD for p in sig.parameters.values())
            for k in kwargs:
                if k not in accepted and not has_var:
                    raise ScenarioError(f"unknown parameter '{k}' for {typ}",
                                        file=self.source, entry=f"{where}.{k}",
                                        hint=did_you_mean(k, accepted)
                                        + f"{typ} takes {accepted}")
            kwargs = self._confine(kwargs, where, out)
            try:
                block = cls(**kwargs)
            except AvError as e:
                raise ScenarioError(str(e), file=self.source, entry=where) from None
            except MemoryError:
                raise ScenarioError(f"{typ}: out of memory", file=self.source, entry=where,
                                    hint="use fewer agents") from None
            except Exception as e:  # noqa: BLE001 - a constructor's own failure
                raise ScenarioError(f"{typ}: {type(e).__name__}: {e}", file=self.source,
                                    entry=where, hint=f"{typ} takes {accepted}") from None
            try:
                d.add(block, name=name)
            except AvError as e:
                raise ScenarioError(str(e), file=self.source, entry=where) from None
        for j, w in enumerate(self.data.get("wires") or []):
            where = f"wires[{j}]"
            if not (isinstance(w, list) and len(w) == 2 and all(isinstance(s, str)
                                                                 for s in w)):
                raise ScenarioError(
                    f"a wire is [\"block.output\", \"block.input\"], found {w!r}",
                    file=self.source, entry=where)
            refs = []
            for s in w:
                b, _, p = s.partition(".")
                if b not in d.blocks:
                    raise ScenarioError(f"wire names unknown block '{b}'",
                                        file=self.source, entry=where,
                                        hint=did_you_mean(b, d.blocks)
                                        + f"blocks: {sorted(d.blocks)}")
                try:
                    refs.append(d[b].port(p))
                except AvError as e:
                    raise ScenarioError(str(e), file=self.source, entry=where) from None
            try:
                d.connect(*refs)
            except AvError as e:
                raise ScenarioError(str(e), file=self.source, entry=where) from None
        try:
            d.build()
        except AvError as e:
            raise ScenarioError(str(e), file=self.source, entry="wires",
                                hint="every input needs exactly one wire") from None
        except Exception as e:  # noqa: BLE001 - a block's configure() failed
            raise ScenarioError(f"building the diagram failed: {type(e).__name__}: {e}",
                                file=self.source, entry="blocks") from None
        sim = {k: self._value(v, f"simulation.{k}")
               for k, v in (self.data.get("simulation") or {}).items()}
        numeric = {k: self._value(v, f"params.{k}")
                   for k, v in (self.data.get("params") or {}).items()}
        if numeric:
            sim["params"] = resolve(d, numeric, self.source, "params")
        return d, sim


def builtin_dir() -> Path:
    return Path(__file__).parent


#: modules of this package that are machinery, not scenarios
INFRASTRUCTURE = ("loader", "report", "paths", "targets", "generators", "limits",
                  "worlds", "files", "document", "scenes")


def builtin_scenarios() -> dict:
    """``{name: path}`` of the scenarios shipped with avblocks: YAML files,
    and Python modules (``make_diagram(**params)``) for those with no YAML
    form. Where both exist the YAML file is the scenario (the module is its
    Python-API twin)."""
    py = [p for p in builtin_dir().glob("*.py") if not p.stem.startswith("_")
          and p.stem not in INFRASTRUCTURE]
    out = {p.stem: p for p in sorted(py)}
    out.update({p.stem: p for p in sorted(builtin_dir().glob("*.yaml"))})
    return dict(sorted(out.items()))


def load_scenario(name_or_path) -> Scenario:
    """A built-in scenario by name, or a YAML/TOML file by path."""
    p = Path(str(name_or_path))
    if not p.is_file():
        # a folder in the working directory named like a built-in scenario
        # never shadows it
        b = builtin_scenarios()
        if str(name_or_path) in b and b[str(name_or_path)].suffix != ".py":
            p = b[str(name_or_path)]
        elif os.path.lexists(p) and not p.is_dir():
            pass                # a FIFO, a device, a link loop: refused by _read, named
        elif p.is_dir():
            raise ScenarioError("is a folder, not a scenario file", file=str(name_or_path),
                                hint=f"built-in scenarios: {sorted(b)}")
        else:
            raise ScenarioError("no such scenario file or built-in scenario",
                                file=str(name_or_path),
                                hint=did_you_mean(name_or_path, b)
                                + f"built-in scenarios: {sorted(b)}")
    data = _read(p)
    sc = Scenario(data if data is not None else {}, str(p))
    sc.validate()
    return sc
