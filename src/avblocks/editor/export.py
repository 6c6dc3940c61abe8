"""A drawn diagram as a Python script that builds it with the public API.

:func:`to_python` turns a scenario mapping (the editor's document without
its layout) into a script: the diagram parameters as variables, each block
constructed with its arguments (generator mappings as calls of the
generator functions, ``$parameter`` references as the variables), the wires
as ``connect`` calls, and :func:`avblocks.simulate` with the simulation
settings. Running the script gives the results the scenario file gives
(tested by running exported scripts against the scenario runs).
"""

from __future__ import annotations

import builtins
import keyword
import re

_REF = re.compile(r"^\$\{?([A-Za-z_][A-Za-z0-9_]*)\}?$")
_SIM_ORDER = ("t_final", "dt", "solver", "log", "log_every", "seed", "realtime")


def _ident(name, taken, prefix):
    """``name`` as a Python identifier not in ``taken``."""
    s = re.sub(r"\W", "_", str(name))
    if not s or s[0].isdigit() or keyword.iskeyword(s) or hasattr(builtins, s) \
            or s in taken:
        s = f"{prefix}{s}"
    while s in taken:
        s += "_"
    taken.add(s)
    return s


class _Writer:
    def __init__(self, data, modules=()):
        from ..scenarios.generators import GENERATORS
        self.data = data
        self.modules = tuple(modules)
        self.generators = GENERATORS
        self.taken = {"av", "np", "GENERATORS", "diagram", "res", "parse_world",
                      "mujoco_scene"}
        self.uses_generators = False
        self.uses_world = False
        self.uses_scene = False
        self.functions = {}                 # "module:name" -> the name in the script
        self.params = {}
        for k in (data.get("parameters") or {}):
            self.params[k] = _ident(k, self.taken, "p_")

    def value(self, v, indent=0) -> str:
        if isinstance(v, str):
            m = _REF.match(v.strip())
            if m and m.group(1) in self.params:
                return self.params[m.group(1)]
            return repr(v)
        if isinstance(v, bool) or v is None or isinstance(v, int):
            return repr(v)
        if isinstance(v, float):
            return repr(v)
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(self.value(x, indent) for x in v) + "]"
        if isinstance(v, dict):
            if len(v) == 1:
                (k, args), = v.items()
                if k in self.generators and isinstance(args, dict):
                    self.uses_generators = True
                    inner = ", ".join(f"{a}={self.value(x, indent)}" for a, x in args.items()
                                      if str(a).isidentifier())
                    if all(str(a).isidentifier() for a in args):
                        return f'GENERATORS["{k}"]({inner})'
                    return (f'GENERATORS["{k}"](**{{'
                            + ", ".join(f"{a!r}: {self.value(x)}" for a, x in args.items())
                            + "})")
                if k == "function" and isinstance(args, str) and ":" in args:
                    # a function the file names by import path (checked by the
                    # loader when the document was validated)
                    if args not in self.functions:
                        self.functions[args] = _ident(args.rpartition(":")[2], self.taken,
                                                      "f_")
                    return self.functions[args]
                if k == "world":
                    self.uses_world = True
                    return f'parse_world({self.value(args)}, "world", ".")'
                if k == "mujoco_scene":
                    self.uses_scene = True
                    return f'mujoco_scene({self.value(args)}, "scene", ".")'
            return "{" + ", ".join(f"{k!r}: {self.value(x, indent)}"
                                   for k, x in v.items()) + "}"
        return repr(v)

    def script(self) -> str:
        d = self.data
        blocks = d.get("blocks") or {}
        lines = []
        imports = {}
        handles = {}
        from ..scenarios.loader import block_registry
        own = block_registry(code_blocks=True, interfaces=True)
        reg = {**block_registry(code_blocks=True, modules=self.modules), **own}
        for name, spec in blocks.items():
            typ = spec["type"]
            cls = reg[typ]
            module = typ.rpartition(".")[0]
            module = f"avblocks.{module}" if typ in own else module
            imports.setdefault(module, set()).add(cls.__name__)
            handles[name] = _ident(name, self.taken, "b_")
        body = []
        body.append(f"diagram = av.Diagram({d.get('name', 'diagram')!r})")
        for name, spec in blocks.items():
            cls = reg[spec["type"]].__name__
            args = [f"{k}={self.value(v)}" for k, v in spec.items() if k != "type"]
            head = f"{handles[name]} = diagram.add({cls}("
            if len(head) + sum(len(a) + 2 for a in args) + len(name) + 12 <= 88:
                body.append(head + ", ".join(args) + f"), name={name!r})")
            else:
                body.append(head)
                body += [f"    {a}," for a in args]
                body.append(f"), name={name!r})")
        body.append("")
        for w in d.get("wires") or []:
            (sb, _, sp), (db, _, dp) = (x.partition(".") for x in w)
            body.append(f"diagram.connect({_port(handles[sb], sp)}, "
                        f"{_port(handles[db], dp)})")
        sim = d.get("simulation") or {}
        kw = [f"{k}={self.value(sim[k])}" for k in _SIM_ORDER if k in sim]
        numeric = d.get("params") or {}
        if numeric:
            kw.append("params={" + ", ".join(f"{k!r}: {self.value(v)}"
                                             for k, v in numeric.items()) + "}")
        body.append("")
        if len(", ".join(kw)) <= 60:
            body.append("res = av.simulate(diagram, " + ", ".join(kw) + ")")
        else:
            body.append("res = av.simulate(")
            body.append("    diagram,")
            body += [f"    {a}," for a in kw]
            body.append(")")
        body.append("print(res)")

        title = str(d.get("name", "diagram"))
        desc = " ".join(str(d.get("description") or "").split())
        lines.append(f'"""{title}: built with the avblocks Python API (exported from '
                     'the editor).')
        if desc:
            lines.append("")
            lines += _wrap(desc.replace('"""', "'''"))
        lines.append('"""')
        lines.append("")
        lines.append("import avblocks as av")
        for module in sorted(imports):
            lines.append(f"from {module} import {', '.join(sorted(imports[module]))}")
        for ref, alias in sorted(self.functions.items()):
            module, _, name = ref.partition(":")
            lines.append(f"from {module} import {name}"
                         + (f" as {alias}" if alias != name else ""))
        if self.uses_generators:
            lines.append("from avblocks.scenarios.generators import GENERATORS")
        if self.uses_world:
            lines.append("from avblocks.scenarios.worlds import _parse_world as parse_world")
        if self.uses_scene:
            lines.append("from avblocks.scenarios.scenes import mujoco_scene")
        lines.append("")
        if self.params:
            lines.append("# the diagram's parameters")
            for k, var in self.params.items():
                lines.append(f"{var} = {self.value(d['parameters'][k])}")
            lines.append("")
        return "\n".join(lines + body) + "\n"


def _port(handle, port):
    """``fleet.pose``, or ``fleet.port("path")`` where the port's name is
    an attribute of the handle itself."""
    from ..core.diagram import BlockHandle
    if port.isidentifier() and not keyword.iskeyword(port) \
            and not hasattr(BlockHandle, port) and not port.startswith("_"):
        return f"{handle}.{port}"
    return f"{handle}.port({port!r})"


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
    may come from (imported by the script under their own names)."""
    return _Writer(data, modules).script()
