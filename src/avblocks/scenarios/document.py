"""Scenario files as editable documents: load to plain JSON, save back keeping the file's form.

A *document* is a scenario file's mapping as plain JSON values (the
block-diagram editor's model, ``src/avblocks/editor/API.md``): ``name``,
``parameters``, ``blocks``, ``wires``, ... and the layout-only ``editor``
section. :func:`load_document` reads one (a file or a built-in case study);
:func:`save_document` writes one back as YAML, atomically, under a root
folder. When the file came from disk, the document is merged into the
file's round-trip tree (ruamel.yaml): every value the document did not
change keeps its original node, so comments, ``$parameter`` references,
generator forms, flow styles and anchors/aliases stay as they were.
:func:`dump_yaml` is the one way from a scenario's data to YAML text.
"""

from __future__ import annotations

import contextlib
import datetime
import hashlib
import io
import stat
from pathlib import Path

from ..core.confined import Confined, FolderError
from ..core.errors import ScenarioError
from .files import _parse, read_scenario
from .limits import MAX_FILE_BYTES, MAX_WIRES, check_values, max_blocks, too_many_blocks

#: Suffixes a document may be saved under.
SAVE_SUFFIXES = (".yaml", ".yml")
#: The order of a scenario file's sections when written fresh.
SECTION_ORDER = ("name", "description", "parameters", "blocks", "wires", "simulation",
                 "params", "movie", "outcome", "figures", "report", "editor")


class DocumentChanged(ScenarioError):
    """The file on disk changed since the document was loaded (its
    ``revision`` differs): saving would overwrite someone else's edit."""


def revision_of(raw: bytes) -> str:
    """The opaque revision of a file's bytes (a SHA-256 prefix)."""
    return hashlib.sha256(raw).hexdigest()[:32]


def _jsonable(v):
    """A parsed YAML/TOML value as plain JSON values (dates as ISO text)."""
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, (datetime.date, datetime.datetime, datetime.time)):
        return v.isoformat()
    if isinstance(v, bool) or v is None or isinstance(v, (int, float, str)):
        return v
    return str(v)


@contextlib.contextmanager
def _opened(root):
    """``root`` as a :class:`~avblocks.core.confined.Confined` folder (opened
    here and closed after, unless it is one already)."""
    if isinstance(root, Confined):
        yield root
        return
    c = Confined(root)
    try:
        yield c
    finally:
        c.close()


def _resolve(name_or_path, root):
    """``(path, builtin name or None)`` of what :func:`load_document` names
    (``root`` None: any path)."""
    from .loader import builtin_scenarios
    target = str(name_or_path)
    b = builtin_scenarios()
    p = Path(target)
    if p.suffix in (".yaml", ".yml", ".toml"):
        if not p.is_file():
            raise ScenarioError("no such scenario file", file=target)
        return p, None
    if target in b:
        if b[target].suffix == ".py":
            raise ScenarioError(f"the built-in case study '{target}' has no scenario file",
                                file=target,
                                hint="it is built by Python code (see "
                                     f"avblocks/scenarios/{target}.py); run it with "
                                     f"`avblocks run {target}`")
        return b[target], target
    if p.is_file():
        raise ScenarioError("is not a scenario file: documents are YAML or TOML "
                            "(.yaml, .yml, .toml)", file=target,
                            hint="a Python scenario module is run with `avblocks run "
                                 "FILE.py`, not drawn")
    from ..core.errors import did_you_mean
    raise ScenarioError("no such scenario file or built-in case study", file=target,
                        hint=did_you_mean(target, b) + f"built-in: {sorted(b)}")


def load_document(name_or_path, root=None) -> dict:
    """A scenario file or built-in case study as a document.

    Parameters
    ----------
    name_or_path : str or path
        A built-in case study's name (``"formation"``), or a ``.yaml`` /
        ``.yml`` / ``.toml`` file (relative to ``root`` when given).
    root : str or path, optional
        The folder files must lie under (the editor's folder); None: any.

    Returns
    -------
    dict
        ``{"document": {...}, "path": str or None, "builtin": str or None,
        "revision": str}``: the file's mapping as plain JSON values (read
        as safely as ``avblocks run`` reads it; not validated, so a draft
        loads as it was saved), the path read
        (relative to ``root`` for files under it; None for a built-in), the
        built-in's name, and the revision of the bytes read.

    Raises
    ------
    ScenarioError
        An unknown name, a file outside ``root``, a file that is not a
        scenario (naming the entry), or a built-in case study that exists
        only as Python code; a file that is not a mapping.
    """
    path = None
    if root is not None and Path(str(name_or_path)).suffix in (".yaml", ".yml", ".toml"):
        # a file under root: read once through the opened folder (no link
        # followed), parsed from the bytes its revision is taken from
        with _opened(root) as c:
            parts = c.split(name_or_path)
            if not parts:
                raise FolderError("a file name is needed", kind="BadPath")
            raw = c.read_bytes(parts, MAX_FILE_BYTES)
            p, builtin, path = c.full(parts), None, c.rel(parts)
        data = _parse(raw, p)
        check_values(data, str(p))    # the limits `avblocks run` applies to the file
    else:
        p, builtin = _resolve(name_or_path, None)
        raw, data = read_scenario(p)  # read once: size, encoding, YAML safety, limits
        if builtin is None:
            path = str(p)
    data = {} if data is None else data
    if not isinstance(data, dict):    # a draft may be invalid, but it is a mapping
        raise ScenarioError("a scenario file is a mapping of sections (name, blocks, "
                            f"wires, ...), found {type(data).__name__}", file=str(p))
    return {"document": _jsonable(data), "path": path, "builtin": builtin,
            "revision": revision_of(raw)}


# ------------------------------------------------------------------ ruamel
def _yaml(indent=None):
    from ruamel.yaml import YAML
    y = YAML(typ="rt")
    y.preserve_quotes = True
    y.width = 4096            # flow values stay on their line, never re-wrapped
    y.representer.add_representer(
        type(None), lambda r, _v: r.represent_scalar("tag:yaml.org,2002:null", "null"))
    if indent is not None:
        y.indent(mapping=indent[0], sequence=indent[1], offset=indent[2])
    else:
        y.indent(mapping=2, sequence=4, offset=2)
    return y


def _plain(node):
    """A ruamel round-trip value as plain Python values (bools as bool)."""
    if isinstance(node, dict):
        return {str(k): _plain(v) for k, v in node.items()}
    if isinstance(node, (list, tuple)):
        return [_plain(v) for v in node]
    from ruamel.yaml.scalarbool import ScalarBoolean
    if isinstance(node, (ScalarBoolean, bool)):
        return bool(node)
    if isinstance(node, int):
        return int(node)
    if isinstance(node, float):
        return float(node)
    if isinstance(node, str):
        return str(node)
    return _jsonable(node)


def _same(a, b) -> bool:
    """``a == b`` as values: bools apart from numbers, 1 == 1.0 (the front
    end's JSON numbers), mappings by keys regardless of order."""
    if isinstance(a, bool) or isinstance(b, bool):
        return isinstance(a, bool) and isinstance(b, bool) and a == b
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    num = (int, float)
    if isinstance(a, num) and isinstance(b, num):
        return a == b
    return type(a) is type(b) and a == b


def _fresh(value, depth=0, key=None):
    """``value`` as ruamel nodes styled like the hand-written files: the
    file, its sections and blocks in block style; short lists and
    mappings (a pose, a generator, a wire) in flow style."""
    import json

    from ruamel.yaml.comments import CommentedMap, CommentedSeq
    if isinstance(value, dict):
        m = CommentedMap()
        for k, v in value.items():
            m[k] = _fresh(v, depth + 1, k)
        block = depth == 0 or (depth == 1 and key in (
            "blocks", "editor", "parameters", "simulation", "params")) or (
            depth == 2 and key in ("layout", "groups")) or len(
            json.dumps(value)) > 72 - 2 * depth
        if depth == 2 and isinstance(value.get("type"), str):
            block = True            # a block's settings
        from .generators import GENERATORS
        if depth >= 2 and len(value) == 1 and next(iter(value)) in GENERATORS:
            block = False           # a generator: one line, as the files write it
        if not block:
            m.fa.set_flow_style()
        else:
            m.fa.set_block_style()
        return m
    if isinstance(value, list):
        s = CommentedSeq(_fresh(v, depth + 1) for v in value)
        s.fa.set_block_style()
        if depth == 1 and key in ("wires", "outcome", "figures"):
            s.fa.set_block_style()
        elif len(json.dumps(value)) <= 72 - 2 * depth or not any(
                isinstance(v, (dict, list)) for v in value):
            s.fa.set_flow_style()
        else:
            s.fa.set_block_style()
        return s
    if isinstance(value, str) and "\n" in value.rstrip("\n"):
        from ruamel.yaml.scalarstring import LiteralScalarString
        return LiteralScalarString(value)
    if isinstance(value, str) and len(value) > 60 and value.endswith("\n"):
        from ruamel.yaml.scalarstring import FoldedScalarString
        return FoldedScalarString(value)
    return value


def _count_refs(node, counts):
    """How often each collection object occurs in the tree (aliases share one)."""
    if isinstance(node, (dict, list)):
        counts[id(node)] = counts.get(id(node), 0) + 1
        if counts[id(node)] > 1:
            return
        for v in (node.values() if isinstance(node, dict) else node):
            _count_refs(v, counts)


def _merge(orig, new, counts, depth=0, key=None):
    """``orig`` (a ruamel node) changed to hold ``new``: the original node
    wherever its value equals the new one; mappings and lists edited in
    place (their comments kept) where they differ."""
    from ruamel.yaml.comments import CommentedMap, CommentedSeq
    if _same(_plain(orig), new):
        return orig
    shared = counts.get(id(orig), 0) > 1        # an anchor used elsewhere too
    if isinstance(orig, CommentedMap) and isinstance(new, dict):
        if shared:
            m = CommentedMap()
            if orig.fa.flow_style():
                m.fa.set_flow_style()
            for k, v in new.items():
                m[k] = _merge(orig[k], v, counts, depth + 1, k) if k in orig else \
                    _fresh(v, depth + 1, k)
            return m
        for k in [k for k in orig if str(k) not in new]:
            del orig[k]
        for k, v in new.items():
            if k in orig:
                merged = _merge(orig[k], v, counts, depth + 1, k)
                if merged is not orig[k]:
                    orig[k] = merged
            else:
                orig[k] = _fresh(v, depth + 1, k)
        if depth == 0 and "editor" in orig and list(orig)[-1] != "editor":
            orig.move_to_end("editor")
        return orig
    if isinstance(orig, CommentedSeq) and isinstance(new, list) and not shared:
        _merge_list(orig, new, counts, depth)
        return orig
    return _fresh(new, depth, key)


def _merge_list(orig, new, counts, depth):
    """Edit the list ``orig`` into ``new``: items kept where equal (a
    removed or inserted wire leaves its neighbours' comments alone),
    changed items merged in place."""
    import difflib
    import json
    a = [json.dumps(_plain(x), sort_keys=True) for x in orig]
    b = [json.dumps(x, sort_keys=True) for x in new]
    ops = difflib.SequenceMatcher(a=a, b=b, autojunk=False).get_opcodes()
    out = []      # (kind, original index or None, new value)
    for tag, i1, i2, j1, j2 in ops:
        if tag == "equal":
            out += [("keep", i1 + k, None) for k in range(i2 - i1)]
        elif tag == "replace" and i2 - i1 == j2 - j1:
            out += [("merge", i1 + k, new[j1 + k]) for k in range(i2 - i1)]
        else:
            out += [("new", None, new[j]) for j in range(j1, j2)]
    # rebuild in place from the back, so that kept items keep their comments
    keep = {i for kind, i, _ in out if i is not None}
    for i in reversed(range(len(orig))):
        if i not in keep:
            del orig[i]
    pos = 0
    for kind, _i, v in out:
        if kind == "keep":
            pass
        elif kind == "merge":
            merged = _merge(orig[pos], v, counts, depth + 1)
            if merged is not orig[pos]:
                orig[pos] = merged
        else:
            orig.insert(pos, _fresh(v, depth + 1))
        pos += 1


def _ordered(document: dict) -> dict:
    known = [k for k in SECTION_ORDER if k in document and k != "editor"]
    rest = [k for k in document if k not in SECTION_ORDER]
    keys = known + rest + (["editor"] if "editor" in document else [])
    return {k: document[k] for k in keys}


def dump_yaml(data: dict, original: str | None = None) -> str:
    """A scenario's data as YAML text.

    Parameters
    ----------
    data : dict
        The scenario mapping (plain values: a document, or
        ``Scenario.data``).
    original : str, optional
        The text of the file the data was loaded from: the data is merged
        into it, keeping what did not change (comments, references,
        generator forms, flow styles, anchors). Unchanged data gives the
        original text back as it is.

    Returns
    -------
    str
        YAML that :func:`avblocks.scenarios.load_scenario` reads back to
        ``data``.
    """
    if original is not None:
        try:
            plain = _safe_load(original)
        except Exception:  # noqa: BLE001 - an unreadable original: written fresh
            plain = None
        if isinstance(plain, dict):
            if _same(_jsonable(plain), data):
                return original
            for attempt in (_spliced, _remerged):
                try:
                    text = attempt(original, data)
                except Exception:  # noqa: BLE001 - the next, plainer way
                    continue
                if text is not None and _reads_back(text, data):
                    return text
    buf = io.StringIO()
    _yaml().dump(_fresh(_ordered(data)), buf)
    return buf.getvalue()


def _safe_load(text):
    import yaml
    return yaml.load(text, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))  # noqa: S506


def _reads_back(text, data) -> bool:
    import yaml
    try:
        return _same(_jsonable(_safe_load(text)), data)
    except yaml.YAMLError:
        return False


def _remerged(original, data):
    """The original tree with the data merged in, dumped whole by ruamel
    (comments and anchors kept; long flow values put on one line)."""
    from ruamel.yaml.util import load_yaml_guess_indent
    _, ind, bsi = load_yaml_guess_indent(original)
    indent = (2, ind or 2, bsi or 0) if ind else None
    tree = _yaml().load(original)
    counts = {}
    _count_refs(tree, counts)
    tree = _merge(tree, data, counts)
    buf = io.StringIO()
    _yaml(indent).dump(tree, buf)
    return buf.getvalue()


def _spliced(original, data, indent=None):
    """The original text with only the changed entries rewritten: block
    mappings and block lists are walked by the line of each key/item
    (ruamel's positions); an entry whose value is unchanged keeps its
    lines byte for byte; a changed one is re-emitted (its merged node, so
    what did not change inside keeps its form and comments)."""
    tree = _yaml().load(original)
    counts = {}
    _count_refs(tree, counts)
    _keep_anchors(tree, set())
    lines = original.splitlines(keepends=True)
    if lines and not lines[-1].endswith("\n"):
        lines[-1] += "\n"
    out = _splice_map(tree, data, lines, 0, len(lines), counts, indent, 0)
    return None if out is None else "".join(out)


def _keep_anchors(node, seen):
    """Mark every anchor of the tree to be written even where its node is
    dumped alone (a re-emitted entry that defines ``&n`` keeps it)."""
    if id(node) in seen or not isinstance(node, (dict, list)):
        return
    seen.add(id(node))
    anchor = getattr(node, "anchor", None)
    if anchor is not None and anchor.value:
        node.yaml_set_anchor(anchor.value, always_dump=True)
    for v in (node.values() if isinstance(node, dict) else node):
        _keep_anchors(v, seen)


def _content_end(lines, a, b):
    """The end of an entry's own lines in ``lines[a:b]``: trailing blank
    and comment-only lines (they precede the next entry) are not its own."""
    end = b
    while end > a + 1 and (not lines[end - 1].strip()
                           or lines[end - 1].lstrip().startswith("#")):
        end -= 1
    return end


def _alias_tokens(node, before, tokens):
    """Replace in ``node`` each anchored value defined above line ``before``
    (kept there as text) by a token that becomes its alias ``*name``."""
    items = list(node.items()) if isinstance(node, dict) else list(enumerate(node))
    for k, v in items:
        if not isinstance(v, (dict, list)):
            continue
        anchor = getattr(v, "anchor", None)
        lc = getattr(v, "lc", None)
        if anchor is not None and anchor.value and lc is not None and lc.line is not None \
                and lc.line < before:
            tok = f"__avblocks_alias_{anchor.value}__"
            node[k] = tok
            tokens[tok] = f"*{anchor.value}"
        else:
            _alias_tokens(v, before, tokens)


def _emit(node, col, indent, before=None):
    """``node`` (a one-entry mapping or a one-item list) dumped by ruamel,
    indented to column ``col``; anchors defined above line ``before`` are
    written as their aliases."""
    import textwrap
    tokens = {}
    if before is not None:
        _alias_tokens(node, before, tokens)
    buf = io.StringIO()
    _yaml(indent).dump(node, buf)
    text = textwrap.dedent(buf.getvalue())
    for tok, alias in tokens.items():
        text = text.replace(tok, alias)
    return [(" " * col + ln) if ln.strip() else ln
            for ln in text.splitlines(keepends=True)]


def _is_block(node):
    from ruamel.yaml.comments import CommentedMap, CommentedSeq
    return isinstance(node, (CommentedMap, CommentedSeq)) and len(node) > 0 and \
        not node.fa.flow_style()


def _splice_map(node, new, lines, lo, hi, counts, indent, depth):
    from ruamel.yaml.comments import CommentedMap
    if not isinstance(new, dict) or not _is_block(node) or counts.get(id(node), 0) > 1:
        return None
    keys = list(node.keys())
    starts = [node.lc.key(k)[0] for k in keys]
    if starts != sorted(starts) or starts[0] < lo or starts[-1] >= hi:
        return None
    col = node.lc.key(keys[0])[1]
    out = list(lines[lo:starts[0]])
    for i, k in enumerate(keys):
        a, b = starts[i], (starts[i + 1] if i + 1 < len(keys) else hi)
        end = _content_end(lines, a, b)
        if str(k) not in new:
            out += lines[end:b]                      # a deleted entry
            continue
        v, nv = node[k], new[str(k)]
        if _same(_plain(v), nv):
            out += lines[a:b]
            continue
        sub = None
        if _is_block(v) and counts.get(id(v), 0) <= 1:
            first = v.lc.key(next(iter(v)))[0] if isinstance(v, CommentedMap) else \
                v.lc.item(0)[0]
            if first > a:                            # its entries on lines of their own
                fn = _splice_map if isinstance(v, CommentedMap) else _splice_seq
                sub = fn(v, nv, lines, a + 1, end, counts, indent, depth + 1)
                if sub is not None:
                    sub = [lines[a]] + sub
        if sub is None:
            m = CommentedMap()
            m[k] = _merge(v, nv, counts, depth + 1, k)
            if k in node.ca.items:
                m.ca.items[k] = node.ca.items[k]
            sub = _emit(m, col, indent, before=a)
        out += sub + lines[end:b]
    added = [k for k in new if k not in node]
    for k in added:
        m = CommentedMap()
        m[k] = _fresh(new[k], depth + 1, k)
        out += _emit(m, col, indent)
    return out


def _splice_seq(node, new, lines, lo, hi, counts, indent, depth):
    import difflib
    import json

    from ruamel.yaml.comments import CommentedSeq
    if not isinstance(new, list) or not _is_block(node) or counts.get(id(node), 0) > 1:
        return None
    starts = [node.lc.item(i)[0] for i in range(len(node))]
    if starts != sorted(starts) or len(set(starts)) != len(starts) or starts[0] < lo \
            or starts[-1] >= hi:
        return None
    line0 = lines[starts[0]]
    dash = line0.rfind("-", 0, node.lc.item(0)[1])
    if dash < 0:
        return None
    out = list(lines[lo:starts[0]])
    a_keys = [json.dumps(_plain(x), sort_keys=True) for x in node]
    b_keys = [json.dumps(x, sort_keys=True) for x in new]
    for tag, i1, i2, j1, j2 in difflib.SequenceMatcher(a=a_keys, b=b_keys,
                                                       autojunk=False).get_opcodes():
        if tag == "equal":
            for i in range(i1, i2):
                out += lines[starts[i]:(starts[i + 1] if i + 1 < len(node) else hi)]
            continue
        olds = list(range(i1, i2))
        for j in range(j1, j2):
            i = olds[j - j1] if j - j1 < len(olds) else None
            item = _merge(node[i], new[j], counts, depth + 1) if i is not None else \
                _fresh(new[j], depth + 1)
            seq = CommentedSeq([item])
            seq.fa.set_block_style()
            out += _emit(seq, dash, indent,
                         before=starts[i] if i is not None else starts[min(i1, len(node) - 1)])
        for i in olds:                                # comment lines after an item
            b = starts[i + 1] if i + 1 < len(node) else hi
            out += lines[_content_end(lines, starts[i], b):b]
    return out


def _origin_text(origin, folder: Confined):
    """The text of the file a document came from (a built-in name or a path
    under ``folder``), or None."""
    if origin is None:
        return None
    from .loader import builtin_scenarios
    b = builtin_scenarios()
    if str(origin) in b and b[str(origin)].suffix in SAVE_SUFFIXES:
        return b[str(origin)].read_bytes().decode("utf-8-sig")
    parts = folder.split(origin)
    if not parts or Path(parts[-1]).suffix not in SAVE_SUFFIXES:
        return None
    try:
        raw = folder.read_bytes(parts, MAX_FILE_BYTES)
    except FolderError as e:
        if e.kind == "NotFound":
            return None
        raise
    return raw.decode("utf-8-sig", errors="replace")


def save_document(path, document, root, revision=None, draft=False, origin=None,
                  create=False) -> dict:
    """Write a document as a YAML scenario file, atomically, under ``root``.

    Parameters
    ----------
    path : str or path
        The file to write, relative to ``root`` (or absolute inside it);
        it must end in ``.yaml`` or ``.yml``.
    document : dict
        The document (see :func:`load_document`).
    root : str, path or Confined
        The only folder written to: opened once and walked by descriptor
        (:class:`~avblocks.core.confined.Confined`), so ``..`` above it and
        symbolic links (even one swapped in while the file is written) are
        refused, and the temporary file lies in the same folder as the file
        and is removed on every exit path.
    revision : str, optional
        The revision :func:`load_document` gave for ``path``: when the file
        on disk no longer has it, :class:`DocumentChanged` is raised and
        nothing is written.
    draft : bool
        False: the document must build (``avblocks run`` would accept it),
        else the build's :class:`ScenarioError` is raised and nothing is
        written. True: written as it is.
    origin : str, optional
        Where the document was loaded from when that is not ``path`` (a
        built-in name, or another file under ``root``): its comments and
        forms are kept in the new file.
    create : bool
        Only create: a file at ``path`` (there before, or appearing while
        this one is written) is left as it is and a
        :class:`~avblocks.core.confined.FolderError` of kind ``Exists`` is
        raised.

    Returns
    -------
    dict
        ``{"path": str (relative to root), "revision": str, "draft": bool}``.
    """
    from .loader import Scenario, check_editor
    if not isinstance(document, dict):
        raise ScenarioError("a document must be a mapping of scenario sections",
                            entry="document")
    with _opened(root) as folder:
        parts = folder.split(path)
        if not parts:
            raise FolderError("a file name is needed", kind="BadPath")
        suffix = Path(parts[-1]).suffix
        if suffix not in SAVE_SUFFIXES:
            raise ScenarioError(f"a scenario file is saved as .yaml or .yml, not "
                                f"'{suffix or parts[-1]}'", file=str(path), entry="path")
        st = folder.stat(parts)
        if st is not None and stat.S_ISDIR(st.st_mode):
            raise ScenarioError("is a folder, not a scenario file", file=str(path))
        if create and st is not None:
            raise FolderError(f"'{folder.rel(parts)}' exists already", kind="Exists")
        blocks = document.get("blocks")
        if isinstance(blocks, dict) and len(blocks) > max_blocks():
            raise too_many_blocks(len(blocks), str(path))
        if isinstance(document.get("wires"), list) and len(document["wires"]) > MAX_WIRES:
            raise ScenarioError(f"{len(document['wires']):,} wires, more than {MAX_WIRES:,}",
                                file=str(path), entry="wires")
        check_editor(document.get("editor"), str(path))
        original = None
        if st is not None:
            raw = folder.read_bytes(parts, MAX_FILE_BYTES)     # a link is refused
            if revision is not None and revision_of(raw) != revision:
                raise DocumentChanged("the file changed on disk since it was loaded",
                                      file=str(path),
                                      hint="load it again, or save under another name")
            original = raw.decode("utf-8-sig", errors="replace")
        elif revision is not None and origin is None:
            raise DocumentChanged("the file was removed since it was loaded", file=str(path),
                                  hint="save again without a revision to create it")
        if original is None:
            original = _origin_text(origin, folder)
        if not draft:
            sc = Scenario(dict(document), str(folder.full(parts)))
            sc.build(output_dir=folder.root / "avblocks-out")
        data = dump_yaml(document, original).encode()
        if len(data) > MAX_FILE_BYTES:
            raise ScenarioError(f"the file would be {len(data) / 1e6:.1f} MB; scenario files "
                                f"are at most {MAX_FILE_BYTES / 1e6:.0f} MB", file=str(path))
        folder.write_atomic(parts, data, exclusive=bool(create))
        return {"path": folder.rel(parts), "revision": revision_of(data),
                "draft": bool(draft)}


__all__ = ["load_document", "save_document", "dump_yaml", "DocumentChanged",
           "revision_of"]
