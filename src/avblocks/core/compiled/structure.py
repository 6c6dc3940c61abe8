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
import types
import weakref

import numpy as np

_MAX_DEPTH = 6
_PLAIN = (type(None), bool, int, float, complex, str, bytes)

#: fingerprints of frozen dataclasses whose fields are plain values (ports):
#: they can never change, so each is worked out once (keyed by value)
_FROZEN: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _plain(v):
    """True for a value that can never change in place (plain scalars and
    tuples of them), whose equality is its structure."""
    if isinstance(v, _PLAIN):
        return True
    return type(v) is tuple and all(_plain(x) for x in v)


def _frozen_fp(obj, depth):
    try:
        fp = _FROZEN.get(obj)
    except TypeError:               # unhashable field: not a plain record
        fp = None
    if fp is not None:
        return fp
    fields = dataclasses.fields(obj)
    values = [getattr(obj, f.name) for f in fields]
    fp = (type(obj).__qualname__,
          tuple((f.name, fingerprint(v, depth + 1)) for f, v in zip(fields, values)))
    if all(_plain(v) for v in values):
        try:
            _FROZEN[obj] = fp
        except TypeError:
            pass
    return fp


def _array_fp(a):
    a = np.ascontiguousarray(a)
    if a.dtype == object:
        return ("objarray", a.shape, tuple(fingerprint(v, 1) for v in a.ravel()))
    h = hashlib.blake2b(memoryview(a).cast("B"), digest_size=16).hexdigest()
    return ("nd", a.dtype.str, a.shape, h)


def fingerprint(obj, depth=0):
    """A hashable value that changes whenever ``obj``'s structure does."""
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
        if all(type(k) is str for k in obj):
            return ("dict", tuple(sorted((k, fingerprint(v, depth + 1))
                                         for k, v in obj.items())))
        return ("dict", tuple(sorted(((repr(k), fingerprint(v, depth + 1))
                                      for k, v in obj.items()), key=lambda kv: kv[0])))
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
    if depth < _MAX_DEPTH and hasattr(obj, "__dict__"):
        return (type(obj).__module__, type(obj).__qualname__,
                fingerprint(vars(obj), depth + 1))
    try:
        hash(obj)
        return ("obj", obj)
    except TypeError:
        return ("id", id(obj), type(obj).__qualname__)


def block_fingerprint(b):
    """Structure of one block: its attributes, with numeric parameters and
    initial state values reduced to shapes and dtypes (they are data) and
    memo attributes (``*_cache``) left out."""
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
            items.append((k, tuple(sorted((n, np.asarray(a).dtype.str, np.shape(a))
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
