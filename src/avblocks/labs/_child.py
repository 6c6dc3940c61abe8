"""The process that runs a student's code (the grader's child).

It is started by :mod:`avblocks.labs.sandbox` as
``python -I -B -c "...; _child.main()" SRC`` (isolated: no current folder,
no user site, no ``PYTHON*`` variables, no bytecode written), in a session
of its own, with the environment of :func:`oscalls.child_environment`.
It only computes: it reads requests from the grader over the data-only
channel (:mod:`avblocks.labs.wire`) and answers each with data. It never
sees an expected value or a verdict.

Start-up, before any of the student's code runs:

1. keep private copies of stdin/stdout as the channel, and point fds 0, 1
   and 2 at the null device (what the student prints goes nowhere);
2. read the configuration (the first message): its folder, its limits,
   the platform features switched off;
3. move into its own temporary folder, set the resource limits
   (:func:`oscalls.apply_limits`), Landlock (:func:`oscalls.restrict_writes`),
   give up every capability (:func:`oscalls.drop_capabilities`) and install
   the seccomp filter (:func:`oscalls.restrict_syscalls`);
4. answer ``{"ready": {what was set}}``.

Requests (``{"id": n, "op": ...}``), each answered ``{"id": n, "ok": value}``
or ``{"id": n, "error": record}``:

``load``
    ``source``, ``filename``, ``names``: execute the source as a fresh
    module; answer which of ``names`` it defines and as what.
``new``
    ``name``, ``args``, ``kwargs``: construct the student's class; answer
    its handle and, for a :class:`~avblocks.core.block.Block`, its
    declarations (ports, states, sample time), from which the grader builds
    a proxy block of its own.
``call`` / ``method``
    ``name`` (and ``obj``), ``args``, ``kwargs``, ``labels``: call the
    student's function or an object's method. Arrays arrive read-only; the
    labels say what each argument is (``input `cmd```), so that a write into
    one is reported by its name.
``bye``
    exit.

An error record says what the student's code raised, where (the deepest
line of the student's file), and what it means (not written yet, a write
into an input, an interrupt, memory); see :func:`error_record`.
"""

from __future__ import annotations

import ast
import dis
import os
import sys
import traceback
import types

import numpy as np

from . import oscalls, wire

_MODULE_NAME = "avblocks_lab_submission"
#: methods that change an array in place
_MUTATORS = {"sort", "fill", "put", "itemset", "resize", "setfield", "partition",
             "byteswap", "setflags"}
#: functions whose first argument is written into
_WRITERS = {"copyto", "place", "putmask", "put_along_axis", "fill_diagonal", "at", "put"}


class _State:
    def __init__(self):
        self.module = None
        self.filename = None
        self.tree = None
        self.objects: dict = {}
        self.limits = wire.DEFAULT
        self.names: tuple = ()
        self.source_lines: list = []


def main():
    """Run the child: set up, then answer requests until ``bye`` or the end
    of the channel."""
    chan_in, chan_out = os.dup(0), os.dup(1)
    null = os.open(os.devnull, os.O_RDWR)
    for fd in (0, 1, 2):
        os.dup2(null, fd)
    os.close(null)

    def read_exact(n):
        buf = bytearray()
        while len(buf) < n:
            chunk = os.read(chan_in, n - len(buf))
            if not chunk:
                raise EOFError
            buf += chunk
        return bytes(buf)

    def send(value):
        data = wire.encode(value, st.limits)
        view = memoryview(data)
        while view:
            view = view[os.write(chan_out, view):]

    st = _State()
    try:
        config, _ = wire.read(read_exact)
    except (EOFError, wire.WireError, OSError):
        os._exit(3)
    oscalls.set_off(config.get("off", []))
    st.limits = wire.Limits(**config.get("wire", {}))
    workdir = config["workdir"]
    os.chdir(workdir)
    done = oscalls.apply_limits(**config.get("limits", {}))
    done.update(oscalls.restrict_writes(workdir))
    done["privileges"] = oscalls.drop_capabilities()
    done.update(oscalls.restrict_syscalls(_protected(config)))
    send({"ready": done, "pid": os.getpid()})

    while True:
        try:
            req, _ = wire.read(read_exact, st.limits, allow_xp=True)
        except (EOFError, OSError):
            os._exit(0)
        except wire.WireError as e:
            send({"id": None, "error": {"kind": "ChannelError", "message": str(e),
                                        "flags": ["channel"]}})
            os._exit(4)
        if not isinstance(req, dict) or req.get("op") == "bye":
            os._exit(0)
        try:
            reply = {"id": req.get("id"), "ok": _handle(st, req)}
        except _Refused as e:
            reply = {"id": req.get("id"), "error": {"kind": "Refused", "message": str(e),
                                                    "flags": ["refused"]}}
        except BaseException as e:  # noqa: BLE001 - the student's code: report it as data
            reply = {"id": req.get("id"), "error": error_record(e, st, req.get("_labelled"))}
        req.pop("_labelled", None)
        try:
            send(reply)
        except wire.WireError as e:
            send({"id": req.get("id"), "error": {
                "kind": "TooLarge", "message": str(e), "flags": ["too_large"],
                "returns": _return_lines(_target(st, req), st.filename)}})


def _protected(config) -> list:
    """The processes the student's code may not signal: the grader and the
    supervisor (this process's parent), their process groups, and every
    process at once (``kill(-1, ...)``)."""
    out = [-1]
    for pid in (config.get("grader"), os.getppid()):
        if type(pid) is int and pid > 1:
            out.append(pid)
            try:
                out.append(-os.getpgid(pid))
            except (OSError, AttributeError):          # gone; Windows has no groups
                pass
    return out


class _Refused(Exception):
    """A request the child cannot serve (no such name, a stale handle)."""


def _target(st, req):
    try:
        if req.get("op") == "method":
            return getattr(st.objects[req["obj"]], req["name"])
        return getattr(st.module, req.get("name", ""), None)
    except Exception:                   # noqa: BLE001
        return None


def _handle(st, req):
    op = req.get("op")
    if op == "load":
        return _load(st, req)
    if st.module is None:
        raise _Refused("no file loaded")
    args, kwargs = list(req.get("args") or []), dict(req.get("kwargs") or {})
    if op == "new":
        name = req.get("name")
        if name not in st.names:
            raise _Refused(f"{name!r} is not one of the lab's names")
        cls = getattr(st.module, name)
        # the constructor's arguments become the object's own data: writable copies
        args = [_writable(a) for a in args]
        kwargs = {k: _writable(v) for k, v in kwargs.items()}
        obj = cls(*args, **kwargs)
        handle = len(st.objects) + 1
        st.objects[handle] = obj
        return {"obj": handle, "type": type(obj).__name__, "block": _describe(obj)}
    if op == "call":
        name = req.get("name")
        if name not in st.names:
            raise _Refused(f"{name!r} is not one of the lab's names")
        fn = getattr(st.module, name)
    elif op == "method":
        try:
            obj = st.objects[req.get("obj")]
        except (KeyError, TypeError):
            raise _Refused("no such object") from None
        name = str(req.get("name"))
        if name.startswith("_"):
            raise _Refused(f"method {name!r} is private")
        fn = getattr(obj, name)
    else:
        raise _Refused(f"unknown request {str(op)[:20]!r}")
    req["_labelled"] = _labelled(fn, args, kwargs, req.get("labels"), req.get("klabels"))
    result = fn(*args, **kwargs)
    if _has_sequence(result):
        return {"value": result, "returns": _return_lines(fn, st.filename)}
    return {"value": result}


def _writable(v):
    if isinstance(v, np.ndarray):
        return np.array(v)
    if isinstance(v, list):
        return [_writable(x) for x in v]
    if isinstance(v, tuple):
        return tuple(_writable(x) for x in v)
    if isinstance(v, dict):
        return {k: _writable(x) for k, x in v.items()}
    return v


def _load(st, req):
    source, filename = req["source"], req["filename"]
    st.names = tuple(req.get("names") or ())
    st.filename = filename
    st.source_lines = source.splitlines()
    code = compile(source, filename, "exec", dont_inherit=True)
    mod = types.ModuleType(_MODULE_NAME)
    mod.__file__ = filename
    sys.modules[_MODULE_NAME] = mod
    exec(code, mod.__dict__)  # noqa: S102 - the student's file, in the student's process
    st.module = mod
    found = {}
    for n in st.names:
        if n in mod.__dict__:
            v = mod.__dict__[n]
            found[n] = "class" if isinstance(v, type) else \
                "function" if callable(v) else "other"
    return {"names": found}


def _describe(obj):
    """The declarations of a student's block (what the grader's proxy
    declares), or None when ``obj`` is not a Block."""
    from ..core.block import Block
    from ..core.sample_times import Inherited, Periodic
    if not isinstance(obj, Block):
        return None
    ins = [[k, None if p.shape is None else list(p.shape), p.dtype, k in obj.feedthrough,
            p.unit, p.agents] for k, p in obj.input_ports.items()]
    outs = [[k, None if p.shape is None else list(p.shape), p.dtype, p.unit, p.agents]
            for k, p in obj.output_ports.items()]
    init = obj.initial_state()
    cst = [[k, init[k]] for k in obj.continuous_states]
    dst = [[k, init[k]] for k in obj.discrete_states]
    stime = obj.sample_time
    if isinstance(stime, Periodic):
        st = ["periodic", float(stime.period), float(stime.offset)]
    elif isinstance(stime, Inherited):
        st = ["inherited"]
    else:
        st = ["continuous"]
    cls = type(obj)
    over = [m for m in ("output", "derivative", "update", "configure")
            if getattr(cls, m, None) is not getattr(Block, m)]
    return {"inputs": ins, "outputs": outs, "cstates": cst, "dstates": dst,
            "random": sorted(obj.random_states), "sample_time": st,
            "update_uses_outputs": bool(obj.update_uses_outputs),
            "side_effects": bool(cls.side_effects), "overrides": over}


# ------------------------------------------------------------------ what went wrong
def _labelled(fn, args, kwargs, labels, klabels):
    """``[(array, label)]`` for every array handed to the student's code."""
    if labels is None:
        import inspect
        try:
            params = list(inspect.signature(fn).parameters)
        except (TypeError, ValueError):
            params = []
        labels = [f"argument `{p}`" for p in params[:len(args)]]
    out = []

    def add(value, label):
        if isinstance(value, np.ndarray):
            out.append((value, label))
        elif isinstance(value, dict):
            for k, v in value.items():
                if isinstance(v, np.ndarray):
                    out.append((v, f"{label} `{k}`"))
    for i, a in enumerate(args):
        lab = labels[i] if i < len(labels) else None
        if lab:
            add(a, lab)
    for k, v in kwargs.items():
        add(v, (klabels or {}).get(k) or f"argument `{k}`")
    return out


def _student_frames(exc, filename):
    if filename is None:
        return []
    return [(fr, ln) for fr, ln in traceback.walk_tb(exc.__traceback__)
            if fr.f_code.co_filename == filename]


def error_record(exc, st, labelled=None) -> dict:
    """What the student's code raised, as data: ``kind`` (the exception's
    type name), ``message``, ``line`` and ``func`` (the deepest frame in the
    student's file), ``flags`` (``not_implemented``, ``interrupt``,
    ``memory``, ``recursion``, ``system_exit``, ``avblocks`` (the library
    refused a value), ``readonly``, ``syntax``), ``readonly`` (the label of
    the input written into) and, for an error the library raised about the
    student's code, ``cause`` (the record of what the student's code
    raised)."""
    try:
        msg = str(exc)
    except Exception:                  # noqa: BLE001 - a hostile __str__
        msg = "(its message could not be read)"
    rec = {"kind": type(exc).__name__[:60], "message": msg[:1000], "flags": []}
    flags = rec["flags"]
    if isinstance(exc, NotImplementedError):
        flags.append("not_implemented")
    if isinstance(exc, KeyboardInterrupt):
        flags.append("interrupt")
    if isinstance(exc, MemoryError):
        flags.append("memory")
    if isinstance(exc, RecursionError):
        flags.append("recursion")
    if isinstance(exc, SystemExit):
        flags.append("system_exit")
    if isinstance(exc, SyntaxError) and st.filename and exc.filename == st.filename:
        flags.append("syntax")
        rec["message"] = str(exc.msg)[:300]
        rec["line"] = exc.lineno
    try:
        from ..core.errors import AvError
        if isinstance(exc, AvError):
            flags.append("avblocks")
    except ImportError:
        pass
    frames = _student_frames(exc, st.filename)
    if frames:
        fr, ln = frames[-1]
        rec["line"] = int(ln)
        rec["func"] = fr.f_code.co_name[:80]
    if isinstance(exc, (ValueError, TypeError)) and "read-only" in msg and labelled:
        rec["readonly"] = _readonly_label(frames, st, labelled)
        flags.append("readonly")
    cause = exc.__cause__ or exc.__context__
    if cause is not None and "avblocks" in flags and not frames:
        sub = error_record(cause, st, labelled) if cause is not exc else None
        if sub and sub.get("line") is not None:
            rec["cause"] = sub
    return rec


def _readonly_label(frames, st, labelled):
    """The label of the input the failing line wrote into, or None."""
    if not frames:
        return labelled[0][1] if len(labelled) == 1 else None
    fr, line = frames[-1]
    found = []
    for expr in _written_exprs(st, line):
        obj = _resolve(expr, fr)
        if isinstance(obj, np.ndarray):
            for arr, label in labelled:
                if np.may_share_memory(obj, arr) and label not in found:
                    found.append(label)
    if len(found) == 1:
        return found[0]
    if not found:                       # any array of the frame that is an input
        for v in list(fr.f_locals.values()):
            if isinstance(v, np.ndarray):
                for arr, label in labelled:
                    if np.may_share_memory(v, arr) and label not in found:
                        found.append(label)
        if len(found) == 1:
            return found[0]
    return None


def _written_exprs(st, line):
    """The expressions the statement at ``line`` of the student's file
    writes into (assignment targets, ``out=``, ``a.sort()``, ``np.copyto(a, ...)``)."""
    if st.tree is None:
        try:
            st.tree = ast.parse("\n".join(st.source_lines))
        except (SyntaxError, ValueError, RecursionError, MemoryError):
            st.tree = False
    if not st.tree:
        return []
    best = None
    for node in ast.walk(st.tree):
        if isinstance(node, ast.stmt) and not isinstance(
                node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef, ast.If,
                       ast.For, ast.While, ast.With, ast.Try)) \
                and node.lineno <= line <= (node.end_lineno or node.lineno):
            if best is None or (node.end_lineno - node.lineno) < (best.end_lineno - best.lineno):
                best = node
    if best is None:
        return []
    out = []
    if isinstance(best, ast.Assign):
        out += best.targets
    elif isinstance(best, (ast.AugAssign, ast.AnnAssign)):
        out.append(best.target)
    for node in ast.walk(best):
        if isinstance(node, ast.Call):
            out += [k.value for k in node.keywords if k.arg == "out"]
            f = node.func
            if isinstance(f, ast.Attribute) and f.attr in _MUTATORS:
                out.append(f.value)
            name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", None)
            if name in _WRITERS and node.args:
                out.append(node.args[0])
    return out


def _resolve(expr, frame):
    """The object ``expr`` names in ``frame`` (names, attributes, constant
    subscripts of dicts and arrays), without running anything else."""
    try:
        if isinstance(expr, ast.Name):
            if expr.id in frame.f_locals:
                return frame.f_locals[expr.id]
            return frame.f_globals.get(expr.id)
        if isinstance(expr, ast.Attribute):
            base = _resolve(expr.value, frame)
            return None if base is None else getattr(base, expr.attr, None)
        if isinstance(expr, ast.Subscript):
            base = _resolve(expr.value, frame)
            if isinstance(base, dict) and isinstance(expr.slice, ast.Constant):
                return base.get(expr.slice.value)
            return base                 # a[...] writes into a
        if isinstance(expr, (ast.Tuple, ast.List)) and expr.elts:
            return _resolve(expr.elts[0], frame)
    except Exception:                   # noqa: BLE001 - a property that raises
        return None
    return None


def _has_sequence(v):
    if isinstance(v, (list, tuple)):
        return True
    if isinstance(v, dict):
        return any(isinstance(x, (list, tuple)) for x in v.values())
    return False


def _return_lines(fn, filename):
    """The lines of ``fn``'s ``return`` statements, when it is the student's."""
    code = getattr(fn, "__code__", None) or getattr(getattr(fn, "__func__", None),
                                                    "__code__", None)
    if code is None or code.co_filename != filename:
        return []
    lines = set()
    try:
        for ins in dis.get_instructions(code):
            if ins.opname in ("RETURN_VALUE", "RETURN_CONST"):
                pos = getattr(ins, "positions", None)
                ln = getattr(pos, "lineno", None) or ins.starts_line
                if ln:
                    lines.add(int(ln))
    except Exception:                   # noqa: BLE001
        return []
    return sorted(lines)[:5]
