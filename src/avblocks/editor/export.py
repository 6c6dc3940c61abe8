"""A drawn diagram as a Python script that builds it with the public API.

:func:`to_python` turns a scenario mapping (the editor's document without
its layout) into a script: the diagram parameters as variables, each block
constructed with its arguments (generator mappings as calls of the
generator functions, ``$parameter`` references as the variables), the wires
as ``connect`` calls, and :func:`avblocks.simulate` with the simulation
settings. Running the script gives the results the scenario file gives
(tested by running exported scripts against the scenario runs).

The script is built as a Python syntax tree (:mod:`ast`) and written by
:func:`ast.unparse`: every text the document holds (its name, description,
parameter names and values, block names and types, wire ends, generator
arguments) lands in the script as a string literal or, for names that
become Python names, as an identifier made of ASCII letters, digits and
``_`` that is checked not to shadow anything. Nothing typed in the editor
is pasted into the script's text, so no name can end a string early or
add a statement. The text is laid out for reading (long calls one argument
per line) and checked to parse to the same tree before it is returned.
"""

from __future__ import annotations

import ast
import builtins
import keyword
import re

from ..core.errors import ScenarioError
from ..scenarios.limits import check_values
from ..scenarios.loader import FUNCTION_REF as _FUNCTION_REF
from ..scenarios.loader import PARAM_REF as _REF

_SIM_ORDER = ("t_final", "dt", "solver", "log", "log_every", "seed", "realtime")
_ASCII_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_DOTTED = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*$")
#: longest identifier made from a user's name (the name itself stays whole
#: in the string literals: ``name='...'``)
_MAX_IDENT = 40
_WIDTH = 88


def _is_name(s) -> bool:
    """An ASCII Python name that is not a keyword (Python folds non-ASCII
    names with NFKC, so two different texts could be one name)."""
    return isinstance(s, str) and bool(_ASCII_NAME.match(s)) and not keyword.iskeyword(s)


def _ident(name, taken, prefix):
    """``name`` as an ASCII Python identifier not in ``taken`` (which it joins)."""
    s = re.sub(r"[^A-Za-z0-9_]", "_", str(name))[:_MAX_IDENT]
    if not s or s[0].isdigit() or keyword.iskeyword(s) or keyword.issoftkeyword(s) \
            or hasattr(builtins, s) or s in taken or s.startswith("__"):
        s = f"{prefix}{s}"
    while s in taken:
        s += "_"
    taken.add(s)
    return s


def _name(ident):
    return ast.Name(ident, ast.Load())


def _const(v):
    return ast.Constant(v)


def _call(func, args=(), kwargs=()):
    """A call; ``kwargs`` as ``(key, value node)``: keyword arguments where the
    key is a plain name, the others gathered into one ``**{...}``."""
    kws, extra = [], []
    for k, v in kwargs:
        if _is_name(k):
            kws.append(ast.keyword(k, v))
        else:
            extra.append((k, v))
    if extra:
        kws.append(ast.keyword(None, ast.Dict([_const(k) for k, _ in extra],
                                              [v for _, v in extra])))
    return ast.Call(func, list(args), kws)


def _attr(obj, name):
    return ast.Attribute(obj, name, ast.Load())


class _Writer:
    def __init__(self, data, modules=()):
        from ..scenarios.generators import GENERATORS
        self.data = data
        self.modules = tuple(str(m) for m in modules)
        self.generators = GENERATORS
        self.taken = {"av", "diagram", "res", "GENERATORS", "parse_world", "mujoco_scene"}
        self.uses_generators = self.uses_world = self.uses_scene = False
        self.functions = {}                 # "module:name" -> the name in the script
        self.params = {}

    # ------------------------------------------------------------ values
    def literal(self, v):
        """``v`` as a plain literal (a parameter's value: the loader hands
        it on as written)."""
        if isinstance(v, (list, tuple)):
            return ast.List([self.literal(x) for x in v], ast.Load())
        if isinstance(v, dict):
            return ast.Dict([_const(k) for k in v], [self.literal(x) for x in v.values()])
        if v is None or isinstance(v, (bool, int, float, str)):
            return _const(v)
        raise ScenarioError(f"a value of type {type(v).__name__} cannot be exported",
                            entry="export", hint="values are numbers, text, lists, mappings")

    def value(self, v):
        """``v`` as the loader resolves it (:meth:`Scenario._value`):
        ``$parameter`` references, generators, functions by import path,
        worlds and MuJoCo scenes as the calls that make them."""
        if isinstance(v, str):
            m = _REF.match(v.strip())
            if m and m.group(1) in self.params:
                return _name(self.params[m.group(1)])
            return _const(v)
        if isinstance(v, (list, tuple)):
            return ast.List([self.value(x) for x in v], ast.Load())
        if isinstance(v, dict):
            if len(v) == 1:
                (k, args), = v.items()
                if k in self.generators and isinstance(args, dict):
                    self.uses_generators = True
                    fn = ast.Subscript(_name("GENERATORS"), _const(k), ast.Load())
                    return _call(fn, kwargs=[(a, self.value(x)) for a, x in args.items()])
                if k == "function":
                    return _name(self.functions[self.function(self.resolved(args))])
                if k == "world":
                    self.uses_world = True
                    return _call(_name("parse_world"),
                                 [self.value(args), _const("world"), _const(".")])
                if k == "mujoco_scene":
                    self.uses_scene = True
                    return _call(_name("mujoco_scene"),
                                 [self.value(args), _const("scene"), _const(".")])
            return ast.Dict([_const(k) for k in v], [self.value(x) for x in v.values()])
        return self.literal(v)

    def resolved(self, v):
        """A ``$parameter`` reference replaced by the parameter's value."""
        if isinstance(v, str):
            m = _REF.match(v.strip())
            params = self.data.get("parameters") or {}
            if m and m.group(1) in params:
                return params[m.group(1)]
        return v

    def function(self, ref):
        """The script's name for the function ``"package.module:name"``
        (imported at the top), checked as the loader checks it."""
        if not isinstance(ref, str) or not _FUNCTION_REF.match(ref):
            raise ScenarioError(f"expected 'package.module:function', found {ref!r:.80}",
                                entry="function")
        mod = ref.partition(":")[0]
        if not any(mod == a or mod.startswith(a + ".") for a in ("avblocks", *self.modules)):
            raise ScenarioError(f"'{mod}' is not a module a file may name", entry="function",
                                hint="functions come from avblocks or a block module "
                                     "given with --blocks")
        self.functions.setdefault(ref, None)       # named before any other name
        return ref

    def scan(self, v):
        """Find the functions ``v`` names (``{function: ...}``), without recursion."""
        stack = [v]
        while stack:
            x = stack.pop()
            if isinstance(x, dict):
                if len(x) == 1 and "function" in x and "function" not in self.generators:
                    self.function(self.resolved(x["function"]))
                    continue
                stack.extend(x.values())
            elif isinstance(x, (list, tuple)):
                stack.extend(x)

    # ------------------------------------------------------------ script
    def _imports(self, blocks):
        """``{block type: local class name}`` and the import statements."""
        from ..scenarios.loader import block_registry
        own = block_registry(code_blocks=True, interfaces=True)
        reg = {**block_registry(code_blocks=True, modules=self.modules), **own}
        local, wanted = {}, {}
        for name, spec in blocks.items():
            typ = spec.get("type") if isinstance(spec, dict) else None
            if not isinstance(typ, str) or typ not in reg:
                raise ScenarioError(f"unknown block type {typ!r:.80}",
                                    entry=f"blocks.{name}.type")
            module, _, attr = typ.rpartition(".")
            module = f"avblocks.{module}" if typ in own else module
            if not (_DOTTED.match(module) and _is_name(attr)):
                raise ScenarioError(f"block type {typ!r:.80} is not an importable name",
                                    entry=f"blocks.{name}.type")
            wanted[typ] = (module, attr)
        for typ, (_module, attr) in sorted(wanted.items()):
            local[typ] = _ident(attr, self.taken, "B_") if attr in self.taken or \
                hasattr(builtins, attr) else attr
            self.taken.add(local[typ])
        return local, wanted

    def script(self) -> str:
        d = self.data
        check_values(d, "<export>")
        blocks = d.get("blocks") or {}
        local, wanted = self._imports(blocks)
        for spec in blocks.values():
            self.scan({k: v for k, v in spec.items() if k != "type"})
        self.scan([d.get("simulation") or {}, d.get("params") or {}])
        for ref in sorted(self.functions):       # imported functions: their own names
            fname = ref.rpartition(":")[2]
            self.functions[ref] = fname if fname not in self.taken and not hasattr(
                builtins, fname) else _ident(fname, self.taken, "f_")
            self.taken.add(self.functions[ref])
        for k in (d.get("parameters") or {}):
            self.params[k] = _ident(k, self.taken, "p_")
        handles = {name: _ident(name, self.taken, "b_") for name in blocks}

        body = []              # (statement, its laid-out text)
        dg = _name("diagram")
        stmt = ast.Assign([ast.Name("diagram", ast.Store())],
                          _call(_attr(_name("av"), "Diagram"),
                                [_const(str(d.get("name", "diagram")))]), lineno=0)
        body.append((stmt, None))
        for name, spec in blocks.items():
            ctor = _call(_name(local[spec["type"]]),
                         kwargs=[(k, self.value(v)) for k, v in spec.items() if k != "type"])
            add = _call(_attr(dg, "add"), [ctor], [("name", _const(name))])
            stmt = ast.Assign([ast.Name(handles[name], ast.Store())], add, lineno=0)
            body.append((stmt, _layout_add(handles[name], ctor, name)))
        body.append(("", None))
        for j, w in enumerate(d.get("wires") or []):
            ends = []
            for s in w:
                b, _, p = str(s).partition(".")
                if b not in handles:
                    raise ScenarioError(f"wire names unknown block {b!r:.80}",
                                        entry=f"wires[{j}]")
                ends.append(_port(handles[b], p))
            body.append((ast.Expr(_call(_attr(dg, "connect"), ends)), None))
        sim = d.get("simulation") or {}
        kw = [(k, self.value(sim[k])) for k in _SIM_ORDER if k in sim]
        numeric = d.get("params") or {}
        if numeric:
            kw.append(("params", ast.Dict([_const(k) for k in numeric],
                                          [self.value(v) for v in numeric.values()])))
        body.append(("", None))
        run = _call(_attr(_name("av"), "simulate"), [dg], kw)
        body.append((ast.Assign([ast.Name("res", ast.Store())], run, lineno=0),
                     _layout_call("res = ", run)))
        body.append((ast.Expr(_call(_name("print"), [_name("res")])), None))

        doc = ast.Expr(_const(_docstring(d)))
        head = [(doc, ast.unparse(ast.Module([doc], []))), ("", None)]
        head.append((ast.Import([ast.alias("avblocks", "av")]), None))
        by_module = {}
        for typ, (module, attr) in wanted.items():
            by_module.setdefault(module, []).append((attr, local[typ]))
        for module in sorted(by_module):
            names = [ast.alias(a, None if a == loc else loc)
                     for a, loc in sorted(set(by_module[module]))]
            head.append((ast.ImportFrom(module, names, 0), None))
        for ref, alias in sorted(self.functions.items()):
            module, _, fname = ref.partition(":")
            head.append((ast.ImportFrom(module, [ast.alias(fname, None if alias == fname
                                                           else alias)], 0), None))
        if self.uses_generators:
            head.append((ast.ImportFrom("avblocks.scenarios.generators",
                                        [ast.alias("GENERATORS")], 0), None))
        if self.uses_world:
            head.append((ast.ImportFrom("avblocks.scenarios.worlds",
                                        [ast.alias("_parse_world", "parse_world")], 0), None))
        if self.uses_scene:
            head.append((ast.ImportFrom("avblocks.scenarios.scenes",
                                        [ast.alias("mujoco_scene")], 0), None))
        head.append(("", None))
        if self.params:
            head.append(("# the diagram's parameters", None))
            for k, var in self.params.items():
                head.append((ast.Assign([ast.Name(var, ast.Store())],
                                        self.literal(d["parameters"][k]), lineno=0), None))
            head.append(("", None))
        return _render(head + body)


def _docstring(d) -> str:
    title = " ".join(str(d.get("name", "diagram")).split())
    text = f"{title}: built with the avblocks Python API (exported from the editor).\n"
    desc = " ".join(str(d.get("description") or "").split())
    if desc:
        text += "\n" + "\n".join(_wrap(desc)) + "\n"
    return text


def _port(handle, port):
    """``fleet.pose``, or ``fleet.port("path")`` where the port's name is
    not a plain name or is an attribute of the handle itself."""
    from ..core.diagram import BlockHandle
    taken = set(dir(BlockHandle)) | {"diagram", "name", "block"}   # and its own fields
    if _is_name(port) and port not in taken and not port.startswith("_"):
        return _attr(_name(handle), port)
    return _call(_attr(_name(handle), "port"), [_const(port)])


def _layout_call(prefix, call, suffix=""):
    """``prefix + call + suffix`` on one line when it fits, else the call's
    arguments one per line; every piece written by :func:`ast.unparse`."""
    one = prefix + ast.unparse(call) + suffix
    if len(one) <= _WIDTH:
        return one
    lines = [prefix + ast.unparse(call.func) + "("]
    lines += [f"    {ast.unparse(a)}," for a in call.args]
    for k in call.keywords:
        lines.append(f"    {k.arg}={ast.unparse(k.value)}," if k.arg is not None
                     else f"    **{ast.unparse(k.value)},")
    lines.append(")" + suffix)
    return "\n".join(lines)


def _layout_add(handle, ctor, name):
    return _layout_call(f"{handle} = diagram.add(", ctor,
                        f", name={ast.unparse(_const(name))})")


def _render(items) -> str:
    """The script's text: each statement laid out (or unparsed), checked to
    parse to the same tree as the statements unparsed plainly."""
    stmts, lines = [], []
    for stmt, text in items:
        if isinstance(stmt, str):
            lines.append(stmt)
            continue
        stmts.append(ast.fix_missing_locations(stmt))
        lines.append(text if text is not None else ast.unparse(stmt))
    text = "\n".join(lines).rstrip("\n") + "\n"
    plain = ast.unparse(ast.Module(stmts, []))
    if ast.dump(ast.parse(text)) != ast.dump(ast.parse(plain)):   # pragma: no cover
        return plain + "\n"                   # the layout lost something: the plain text
    return text


def _wrap(text, width=76):
    out, line = [], ""
    for word in text.split():
        if line and len(line) + 1 + len(word) > width:
            out.append(line)
            line = word
        else:
            line = f"{line} {word}" if line else word
    if line:
        out.append(line)
    return out


def to_python(data: dict, modules=()) -> str:
    """The Python script that builds and simulates the scenario mapping
    ``data`` (a valid one: block types from the registry, wires as
    ``"block.port"`` pairs); ``modules``: the user block modules its types
    may come from (imported by the script under their own names).

    Every text of ``data`` reaches the script as a literal or as a checked
    ASCII identifier (see the module docstring); a value past the scenario
    limits, a type outside the registry or a function outside the allowed
    modules is a :class:`~avblocks.core.errors.ScenarioError`."""
    if not isinstance(data, dict):
        raise ScenarioError("a scenario is a mapping of sections", entry="export")
    return _Writer(data, modules).script()
