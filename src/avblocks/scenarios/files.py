"""Reading a scenario file safely: size limit, UTF-8, YAML without aliases
bombs or duplicate keys, TOML; every failure a :class:`ScenarioError` naming
the file and the position."""

from __future__ import annotations

import re
from pathlib import Path

from ..core.errors import ScenarioError
from .limits import (
    MAX_FILE_BYTES,
    MAX_YAML_NODES,
    MAX_YAML_VALUES,
    max_blocks,
    too_many_blocks,
)


def _yaml_error(e):
    """A PyYAML error in one line with its position."""
    import yaml
    if isinstance(e, yaml.MarkedYAMLError):
        m = e.problem_mark or e.context_mark
        what = " ".join(str(e.problem or e.context or "invalid YAML").split())
        if e.context and e.problem:
            what = " ".join(f"{e.problem} ({e.context})".split())
        return what + (f" at line {m.line + 1}, column {m.column + 1}" if m else "")
    return " ".join(str(e).split())


def _expanded_size(node, limit):
    """Number of values ``node`` expands to (aliases counted every time they
    are used), computed on the graph without expanding it; ``limit + 1`` as
    soon as it passes ``limit``; -1 for a recursive structure."""
    import yaml
    size, state = {}, {}
    stack = [(node, False)]
    while stack:
        n, done = stack.pop()
        key = id(n)
        if done:
            kids = _children(n, yaml)
            size[key] = min(limit + 1, 1 + sum(size[id(c)] for c in kids))
            state[key] = 2
            continue
        if state.get(key) == 2:
            continue
        if state.get(key) == 1:
            return -1
        state[key] = 1
        stack.append((n, True))
        for c in _children(n, yaml):
            if state.get(id(c)) == 1:
                return -1
            if state.get(id(c)) != 2:
                stack.append((c, False))
    return size[id(node)]


def _children(n, yaml):
    if isinstance(n, yaml.SequenceNode):
        return list(n.value)
    if isinstance(n, yaml.MappingNode):
        return [x for kv in n.value for x in kv]
    return []


def _prescan(text, source):
    """Count the file's nodes, and the entries of its top-level ``blocks``
    mapping, with libyaml's event parser before anything is composed or
    built: a file with too many blocks (or nodes) is refused in
    milliseconds, not after a parse of tens of seconds. Syntax errors are
    left to the real parse (which words them)."""
    import yaml
    blocks_limit = max_blocks()
    parser = getattr(yaml, "CSafeLoader", yaml.SafeLoader)(text)
    node_events = (yaml.ScalarEvent, yaml.AliasEvent, yaml.MappingStartEvent,
                   yaml.SequenceStartEvent)
    stack = []            # open collections: [is_mapping, children seen, is_blocks]
    nodes = 0
    blocks_next = False   # the next node is the value of the top-level 'blocks' key
    try:
        while parser.check_event():
            ev = parser.get_event()
            if isinstance(ev, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
                stack.pop()
                continue
            if isinstance(ev, yaml.DocumentStartEvent):
                stack, blocks_next = [], False
            if not isinstance(ev, node_events):
                continue
            nodes += 1
            if nodes > MAX_YAML_NODES:
                raise ScenarioError(f"the file holds more than {MAX_YAML_NODES:,} values",
                                    file=source, hint="generate large data (generators) "
                                                      "instead of writing it out")
            is_blocks, blocks_next = blocks_next, False
            if stack:
                parent = stack[-1]
                is_key = parent[0] and parent[1] % 2 == 0
                parent[1] += 1
                if is_key and parent[2] and parent[1] // 2 + 1 > blocks_limit:
                    raise too_many_blocks(None, source)
                if (is_key and len(stack) == 1 and isinstance(ev, yaml.ScalarEvent)
                        and ev.value == "blocks"):
                    blocks_next = True
            if isinstance(ev, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
                stack.append([isinstance(ev, yaml.MappingStartEvent), 0, is_blocks])
    except yaml.YAMLError:
        return
    finally:
        parser.dispose()


_TOML_HEADER = re.compile(r"^\s*\[\[?\s*([^\]]*?)\s*\]")
_TOML_KEY = re.compile(r"^\s*([A-Za-z0-9_\-.\s\"']+?)\s*=")


def _toml_prescan(text, source):
    """A TOML file's blocks counted line by line before ``tomllib`` parses it
    (seconds for a few MB): table headers ``[blocks.x]``, dotted keys
    ``blocks.x.type = ...`` and keys of a ``[blocks]`` table. A heuristic
    that sees the usual ways of writing blocks; the count after parsing
    (:meth:`Scenario.validate`) is the exact check."""
    limit = max_blocks()
    names, table = set(), ""
    for line in text.splitlines():
        m = _TOML_HEADER.match(line)
        if m:
            table = m.group(1).replace(" ", "").replace('"', "").replace("'", "")
            parts = table.split(".")
            if len(parts) >= 2 and parts[0] == "blocks":
                names.add(parts[1])
        else:
            m = _TOML_KEY.match(line)
            if not m:
                continue
            key = m.group(1).replace(" ", "").replace('"', "").replace("'", "")
            full = (table + "." + key if table else key).split(".")
            if len(full) >= 2 and full[0] == "blocks":
                names.add(full[1])
        if len(names) > limit:
            raise too_many_blocks(None, source)


def _safe_yaml(text, source):
    """``yaml.safe_load`` that refuses duplicate keys, unhashable keys and
    alias expansions past :data:`MAX_YAML_VALUES`.

    Parsed with libyaml (``CSafeLoader``, ten times faster: a 500-block file
    in 0.3 s instead of 3 s) where PyYAML has it; a file libyaml refuses is
    parsed again by the pure-Python loader, so an error reads the same
    everywhere."""
    import yaml
    fast = getattr(yaml, "CSafeLoader", None)
    if fast is not None:
        _prescan(text, source)
        try:
            return _compose_checked(text, source, fast, prescan=False)
        except yaml.YAMLError:
            pass                       # worded by the pure-Python parser below
    return _compose_checked(text, source, yaml.SafeLoader, prescan=fast is None)


def _compose_checked(text, source, base, prescan=True):
    import yaml

    class Loader(base):
        pass

    def mapping(loader, node, deep=False):
        seen = set()
        for k_node, _v in node.value:
            if k_node.tag == "tag:yaml.org,2002:merge":
                continue
            k = loader.construct_object(k_node, deep=True)
            try:
                hash(k)
            except TypeError:
                raise yaml.constructor.ConstructorError(
                    None, None, "a mapping key must be a plain value",
                    k_node.start_mark) from None
            if k in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicate key {k!r}", k_node.start_mark)
            seen.add(k)
        return base.construct_mapping(loader, node, deep=deep)

    Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, mapping)
    if prescan:
        _prescan(text, source)
    loader = Loader(text)
    try:
        node = loader.get_single_node()
        if node is None:
            return None
        n = _expanded_size(node, MAX_YAML_VALUES)
        if n < 0:
            raise ScenarioError("anchors/aliases make a recursive structure",
                                file=source)
        if n > MAX_YAML_VALUES:
            raise ScenarioError(f"anchors/aliases expand to more than {MAX_YAML_VALUES:,} "
                                "values", file=source,
                                hint="write the data out or use a generator")
        return loader.construct_document(node)
    finally:
        loader.dispose()


def _read(path: Path):
    source = str(path)
    if path.is_dir():
        raise ScenarioError("is a folder, not a scenario file", file=source)
    try:
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise ScenarioError(f"the file is {size / 1e6:.1f} MB; scenario files are "
                                f"at most {MAX_FILE_BYTES / 1e6:.0f} MB", file=source)
        raw = path.read_bytes()
    except OSError as e:
        raise ScenarioError(f"cannot read: {e.strerror or e}", file=source) from None
    return _parse(raw, path)


def _parse(raw: bytes, path: Path):
    """The values of a scenario file's bytes ``raw`` (YAML or TOML by
    ``path``'s suffix), as :func:`_read` parses them."""
    source = str(path)
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise ScenarioError(f"not UTF-8 text (byte 0x{raw[e.start]:02x} at offset "
                            f"{e.start})", file=source,
                            hint="save the file as UTF-8") from None
    if path.suffix in (".yaml", ".yml"):
        import yaml
        try:
            return _safe_yaml(text, source)
        except ScenarioError:
            raise
        except yaml.YAMLError as e:
            raise ScenarioError(f"cannot parse: {_yaml_error(e)}", file=source) from None
        except RecursionError:
            raise ScenarioError("cannot parse: the file nests values too deeply",
                                file=source) from None
        except Exception as e:  # noqa: BLE001 - constructors of odd YAML scalars
            raise ScenarioError(f"cannot parse: {type(e).__name__}: {e}",
                                file=source) from None
    if path.suffix == ".toml":
        import tomllib
        _toml_prescan(text, source)
        try:
            return tomllib.loads(text)
        except RecursionError:
            raise ScenarioError("cannot parse: the file nests values too deeply",
                                file=source) from None
        except Exception as e:  # noqa: BLE001 - tomllib errors
            raise ScenarioError(f"cannot parse: {' '.join(str(e).split())}",
                                file=source) from None
    raise ScenarioError("unknown scenario file type", file=source,
                        hint="use .yaml, .yml or .toml (or a .py file)")
