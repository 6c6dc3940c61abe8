"""The compile-cache key: everything a trace bakes in, nothing it takes as data.

A compiled run takes the numeric parameters and the initial states (random
keys included) as arguments. Everything else a block holds is *structural*
and becomes a constant of the trace: block types, wiring, port and state
shapes and dtypes, sample times, the shapes of the numeric parameters, and
the values of every other attribute (e.g. a controller's waypoint table
while it is not a declared parameter). The key fingerprints all of that, so
two diagrams with the same key can share one compiled program, and a change
to any structural value gives a new key (a new compile, never a stale one).

Arrays are fingerprinted by content (BLAKE2b of their bytes); callables by
identity (a :class:`~avblocks.blocks.Function` block built anew from a new
``lambda`` compiles anew). Values a function reads from module globals are
not seen: change those only by declaring them as parameters.
"""

from __future__ import annotations

import dataclasses
import hashlib
import operator
import threading
import types
import weakref

import numpy as np

from ..block import Block as _Block


class _Mode(threading.local):
    strip = False       # plan_key: leave the searches' plans out

    def __init__(self):
        self.visiting = set()   # ids of the blocks being fingerprinted


_MODE = _Mode()


_MAX_DEPTH = 6
_PLAIN = (type(None), bool, int, float, complex, str, bytes)
_PLAIN_TYPES = frozenset(_PLAIN)

def _plain(v):
    """True for a value that can never change in place (plain scalars and
    tuples of them), whose equality is its structure."""
    if type(v) in _PLAIN_TYPES:
        return True
    return type(v) is tuple and all(_plain(x) for x in v)


#: id -> (weak reference, fingerprint) of frozen dataclasses of plain values
#: (ports, sample times): they never change, so each is looked at once
_FROZEN: dict = {}
#: type -> whether it is a frozen dataclass
_IS_FROZEN: dict = {}


def _frozen_fp(obj, depth):
    """A frozen dataclass of plain values (a port, a sample time) is its own
    fingerprint: it compares by value and can never change. Others are
    fingerprinted field by field."""
    hit = _FROZEN.get(id(obj))
    if hit is not None and hit[0]() is obj:
        return hit[1]
    fields = dataclasses.fields(obj)
    values = [getattr(obj, f.name) for f in fields]
    if not all(_plain(v) for v in values):
        return (type(obj).__qualname__,
                tuple((f.name, fingerprint(v, depth + 1)) for f, v in zip(fields, values)))
    fp = ("frozen", obj)
    key = id(obj)
    try:
        ref = weakref.ref(obj, lambda _r, key=key, memo=_FROZEN: memo.pop(key, None))
    except TypeError:               # not weakly referable: not remembered
        return fp
    _FROZEN[key] = (ref, fp)
    return fp


#: arrays up to this size are fingerprinted by their bytes (cheaper than a hash)
_SMALL_ARRAY = 512


def _array_fp(a):
    a = np.ascontiguousarray(a)
    if a.dtype == object:
        return ("objarray", a.shape, tuple(fingerprint(v, 1) for v in a.ravel()))
    if a.nbytes <= _SMALL_ARRAY:
        return ("nd", a.dtype.str, a.shape, a.tobytes())
    h = hashlib.blake2b(memoryview(a).cast("B"), digest_size=16).hexdigest()
    return ("nd", a.dtype.str, a.shape, h)


def fingerprint(obj, depth=0):
    """A hashable value that changes whenever ``obj``'s structure does."""
    t = type(obj)
    if t in _PLAIN_TYPES:
        return (t.__name__, obj)
    if t is np.ndarray:
        return _array_fp(obj)
    if t is dict:
        return _dict_fp(obj, depth)
    frozen = _IS_FROZEN.get(t)
    if frozen is None:
        frozen = _IS_FROZEN[t] = (dataclasses.is_dataclass(t) and not isinstance(obj, type)
                                  and t.__dataclass_params__.frozen)
    if frozen:
        return _frozen_fp(obj, depth)
    if (t is set or t is frozenset) and all(type(v) is str for v in obj):
        return ("set", tuple(sorted(obj)))
    if obj is None or isinstance(obj, (bool, int, float, complex, str, bytes)):
        return (type(obj).__name__, obj)
    if isinstance(obj, np.ndarray):
        return _array_fp(obj)
    if isinstance(obj, np.generic):
        return ("np", obj.dtype.str, obj.item())
    if isinstance(obj, np.dtype):
        return ("dtype", obj.str)
    if isinstance(obj, (list, tuple)):
        return (type(obj).__name__, tuple(fingerprint(v, depth + 1) for v in obj))
    if isinstance(obj, dict):
        return _dict_fp(obj, depth)
    if isinstance(obj, (set, frozenset)):
        return ("set", tuple(sorted(repr(fingerprint(v, depth + 1)) for v in obj)))
    if isinstance(obj, (types.FunctionType, types.BuiltinFunctionType, types.MethodType,
                        types.ModuleType, type)):
        return ("ref", obj)           # identity; the key holds the object alive
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        if obj.__dataclass_params__.frozen:
            return _frozen_fp(obj, depth)
        return (type(obj).__qualname__,
                tuple((f.name, fingerprint(getattr(obj, f.name), depth + 1))
                      for f in dataclasses.fields(obj)))
    slots = getattr(type(obj), "__slots__", None)
    if depth < _MAX_DEPTH and slots and not hasattr(obj, "__dict__"):
        slots = (slots,) if isinstance(slots, str) else slots
        return (type(obj).__qualname__,
                tuple((s, fingerprint(getattr(obj, s, None), depth + 1)) for s in slots))
    if isinstance(obj, _Block):
        # a block held by another (a helper's back-reference to its owner):
        # its structure as a block's, numeric parameters as shapes; a block
        # met again inside itself by its type
        if id(obj) in _MODE.visiting:
            return ("block-ref", type(obj).__module__, type(obj).__qualname__)
        return block_fingerprint(obj)
    if depth < _MAX_DEPTH and hasattr(obj, "__dict__"):
        attrs = vars(obj)
        if _MODE.strip and getattr(t, "neighbor_search", False) and \
                not getattr(obj, "fixed", False):
            attrs = {k: v for k, v in attrs.items() if k != "cells"}   # the plan
        return (type(obj).__module__, type(obj).__qualname__,
                fingerprint(attrs, depth + 1))
    try:
        hash(obj)
        return ("obj", obj)
    except TypeError:
        return ("id", id(obj), type(obj).__qualname__)


def _dict_fp(obj, depth):
    if all(type(k) is str for k in obj):
        return ("dict", tuple(sorted((k, fingerprint(v, depth + 1))
                                     for k, v in obj.items())))
    return ("dict", tuple(sorted(((repr(k), fingerprint(v, depth + 1))
                                  for k, v in obj.items()), key=lambda kv: kv[0])))


def block_fingerprint(b):
    """Structure of one block: its attributes, with numeric parameters and
    initial state values reduced to shapes and dtypes (they are data) and
    memo attributes (``*_cache``) left out."""
    visiting = _MODE.visiting
    if id(b) in visiting:
        return ("block-ref", type(b).__module__, type(b).__qualname__)
    visiting.add(id(b))
    try:
        return _block_fingerprint(b)
    finally:
        visiting.discard(id(b))


def _block_fingerprint(b):
    params = b._params
    items = []
    for k, v in vars(b).items():
        if k.endswith("_cache"):            # memo of values (e.g. Block.param_flag)
            continue
        if k in params:
            items.append((k, ("param", tuple(np.shape(v)))))
        elif k == "_params":
            # the specs' bounds, units and docs only validate values: the
            # trace sees each parameter's name and shape
            items.append((k, tuple((n, p.shape) for n, p in v.items())))
        elif k == "_init":
            items.append((k, tuple(sorted(
                (n, np.asarray(a).dtype.str) + (() if _MODE.strip else (np.shape(a),))
                for n, a in v.items()))))
        else:
            items.append((k, fingerprint(v, 1)))
    items.sort(key=lambda kv: kv[0])
    return (type(b).__module__, type(b).__qualname__, tuple(items))


def diagram_key(compiled):
    """Key of a compiled diagram's structure (see the module docstring)."""
    return (tuple(compiled.names),
            tuple(tuple(sorted(s.items())) for s in compiled.sources),
            tuple(block_fingerprint(b) for b in compiled.blocks))




def plan_key(compiled):
    """The structure of a compiled diagram *without* the plans of its
    neighbour searches (:mod:`avblocks.core.compiled.plans`): the key under
    which a grown plan is kept, the same before planning and after growing.
    The plans a user fixed (``capacity=``) are kept in it; the shapes of
    the states are left out (a block may size a state by its plan, the
    Verlet list of ``environment.Neighbors``), their names and dtypes kept."""
    _MODE.strip = True
    try:
        return diagram_key(compiled)
    finally:
        _MODE.strip = False


class Unstable(Exception):
    """A key holds something that has no meaning in another process."""


def stable_digest(key) -> str | None:
    """A hex digest of ``key`` (from :func:`diagram_key` or :func:`plan_key`)
    that is the same in every process, or None when the key holds
    something that is not (an object known by its identity only, a
    ``lambda``): such a structure is not stored on disk."""
    h = hashlib.blake2b(digest_size=20)
    try:
        _feed(h, key)
    except Unstable:
        return None
    return h.hexdigest()


def _feed(h, v):
    t = type(v)
    if t is tuple or t is list:
        h.update(b"(")
        for x in v:
            _feed(h, x)
        h.update(b")")
    elif t in _PLAIN_TYPES or isinstance(v, (np.generic, np.dtype)):
        h.update(f"{t.__name__}:{v!r};".encode())
    elif isinstance(v, types.FunctionType):
        if v.__name__ == "<lambda>" or "<locals>" in v.__qualname__:
            raise Unstable(v)
        h.update(f"fn:{v.__module__}.{v.__qualname__};".encode())
    elif isinstance(v, type):
        h.update(f"type:{v.__module__}.{v.__qualname__};".encode())
    elif isinstance(v, (types.BuiltinFunctionType, types.ModuleType)):
        h.update(f"ref:{getattr(v, '__module__', '')}.{v.__name__};".encode())
    else:
        r = repr(v)
        if " at 0x" in r or " object at " in r:
            raise Unstable(v)
        h.update(f"{t.__module__}.{t.__qualname__}:{r};".encode())


def _stable(v):
    """True for a value that can never change in place: plain values,
    tuples of them, frozen dataclasses of plain values."""
    if _plain(v):
        return True
    return bool(_IS_FROZEN.get(type(v))) and _frozen_fp(v, 1)[0] == "frozen"


def _token(k, v, params):
    """``(kind, value)``: what must stay the same for attribute ``k`` of a
    block (value ``v``) to keep its part of :func:`block_fingerprint`."""
    t = type(v)
    if k in params:
        return ("shape", np.shape(v))
    if k == "_params":
        return ("specs", tuple((n, p.shape) for n, p in v.items()))
    if k == "_init":
        return ("init", tuple((n, np.asarray(a).dtype.str, np.shape(a))
                              for n, a in v.items()))
    if _stable(v):
        return ("same", v)                          # the same object
    if t is np.ndarray and v.dtype != object:
        return ("array", _array_fp(v))
    if t is dict and all(_stable(x) for x in v.values()):
        return ("items", (tuple(v), tuple(v.values())))
    if (t is set or t is frozenset) and all(type(x) is str for x in v):
        return ("set", frozenset(v))
    return ("fp", fingerprint(v, 1))


def _same_token(kind, tok, k, now, params):
    if kind == "same":
        return now is tok
    if kind == "array":
        return type(now) is np.ndarray and _array_fp(now) == tok
    if kind == "items":
        return (type(now) is dict and tuple(now) == tok[0]
                and all(map(operator.is_, now.values(), tok[1])))
    if kind == "set":
        return type(now) in (set, frozenset) and now == tok
    # the tokens worked out afresh below, read without building them when
    # the values are arrays (a miss still builds the token: same answer)
    if kind == "shape" and type(now) is np.ndarray and now.shape == tok:
        return True
    if kind == "init" and type(now) is dict and len(now) == len(tok) and all(
            type(a) is np.ndarray and n == m and a.shape == shp and a.dtype.str == dt
            for (n, a), (m, dt, shp) in zip(now.items(), tok)):
        return True
    if kind == "specs" and type(now) is dict and len(now) == len(tok) and all(
            n == m and p.shape == shp for (n, p), (m, shp) in zip(now.items(), tok)):
        return True
    return _token(k, now, params) == (kind, tok)


class Snapshot:
    """A quick test that a compiled diagram's blocks still have the
    structure they had when it was taken (the same :func:`diagram_key`):
    attributes that cannot change in place are compared by identity, arrays
    by content, dicts of unchangeable values by their items, anything else
    by its fingerprint. ``matches()`` True implies the same key; False only
    means "work the key out" (a parameter's bounds changed, say)."""

    def __init__(self, compiled):
        self.blocks = []
        for b in compiled.blocks:
            attrs = vars(b)
            toks = [(k, *_token(k, v, b._params)) for k, v in attrs.items()
                    if not k.endswith("_cache")]
            self.blocks.append((b, type(b), tuple(attrs), toks))

    def matches(self):
        for b, cls, keys, toks in self.blocks:
            attrs = vars(b)
            if type(b) is not cls or tuple(attrs) != keys:
                return False
            params = b._params
            for k, kind, tok in toks:
                if not _same_token(kind, tok, k, attrs[k], params):
                    return False
        return True
