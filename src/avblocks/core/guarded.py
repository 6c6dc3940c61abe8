"""Block constructors that fail well: a plain Python/NumPy error raised on a
user's arguments becomes a :class:`ParameterError` (or ``ParameterTypeError``)
naming the block, the argument the message quotes, and the constructor's
signature. :class:`~avblocks.core.block.Block` wraps every subclass's
``__init__`` with :func:`_guard_init`."""

from __future__ import annotations

import weakref

#: The arguments each block was constructed with (outermost constructor
#: call), kept beside the block so they never enter its attributes (the
#: compiled engine's structure keys read those).
_ARGUMENTS = weakref.WeakKeyDictionary()


def constructor_arguments(block) -> dict:
    """``{name: value}`` of the arguments ``block`` was constructed with, as
    the call gave them (defaults not filled in); ``{}`` when unknown. Tools
    that turn a diagram built in Python back into data (the editor) read
    this."""
    import inspect
    try:
        args, kwargs = _ARGUMENTS[block]
    except (KeyError, TypeError):
        return {}
    try:
        bound = inspect.signature(type(block).__init__).bind(block, *args, **kwargs)
    except TypeError:
        return {}
    out = {}
    for k, v in bound.arguments.items():
        if k == "self":
            continue
        kind = inspect.signature(type(block).__init__).parameters[k].kind
        if kind == inspect.Parameter.VAR_KEYWORD:
            out.update(v)
        elif kind != inspect.Parameter.VAR_POSITIONAL:
            out[k] = v
    return out


def _guard_init(cls, init, before=None):
    """Wrap a block constructor so that a plain Python/NumPy error raised on
    the user's arguments (a bare ``int()`` of a string, a negative size, an
    overflow) becomes a :class:`ParameterError` naming the block, instead
    of leaking from deep inside. A ``TypeError`` stays a ``TypeError`` too
    (``ParameterTypeError``), so unknown keywords are still TypeErrors.
    ``before(cls, arguments)``, when given, checks the bound arguments
    (``{name: value}``) before the constructor runs."""
    import functools

    from .errors import AvError, ParameterError, ParameterTypeError

    @functools.wraps(init)
    def __init__(self, *args, **kwargs):
        try:
            if self not in _ARGUMENTS:          # the outermost constructor's call
                _ARGUMENTS[self] = (args, dict(kwargs))
        except TypeError:                       # a block that cannot be weakly referenced
            pass
        try:
            if before is not None and (args or kwargs):
                bound = _bound(init, self, args, kwargs)
                if bound is not None:
                    before(cls, bound)
            init(self, *args, **kwargs)
        except AvError:
            raise
        except TypeError as e:
            raise ParameterTypeError(_ctor_msg(e), block=cls.__name__,
                                     param=_culprit(init, self, args, kwargs, e),
                                     hint=_ctor_hint(init)) from e
        except MemoryError:
            raise ParameterError("the arguments ask for more memory than there is",
                                 block=cls.__name__,
                                 hint="use fewer agents or smaller sizes") from None
        except (ValueError, OverflowError, ZeroDivisionError, IndexError, KeyError,
                FloatingPointError) as e:
            param = _culprit(init, self, args, kwargs, e)
            empty = None if param is not None else _empty_argument(init, self, args, kwargs)
            if empty is not None:       # NumPy's words for it ("zero-size array ...") say less
                raise ParameterError("is empty", block=cls.__name__, param=empty[0],
                                     expected="at least one entry (one per agent)",
                                     found=f"shape {empty[1]}") from e
            raise ParameterError(_ctor_msg(e), block=cls.__name__, param=param,
                                 hint=_ctor_hint(init)) from e

    __init__._av_guarded = True
    return __init__


def _bound(init, self, args, kwargs):
    import inspect
    try:
        return inspect.signature(init).bind(self, *args, **kwargs).arguments
    except (TypeError, ValueError):
        return None


def _empty_argument(init, self, args, kwargs):
    """``(name, shape)`` of the one array argument that is empty (the agent
    count 0 makes per-agent arrays empty), else None."""
    import numpy as np
    bound = _bound(init, self, args, kwargs)
    if bound is None:
        return None
    hits = []
    for k, v in bound.items():
        if k == "self" or not isinstance(v, (list, tuple, np.ndarray)):
            continue
        try:
            a = np.asarray(v, dtype=float)
        except (TypeError, ValueError):
            continue
        if a.size == 0:
            hits.append((k, a.shape))
    return hits[0] if len(hits) == 1 else None


def _culprit(init, self, args, kwargs, e):
    """The argument the error message quotes, when exactly one does."""
    import inspect
    try:
        bound = inspect.signature(init).bind(self, *args, **kwargs)
    except TypeError:
        return None
    msg = str(e)
    hits = []
    for k, v in bound.arguments.items():
        if k == "self" or isinstance(v, (bool, type(None))):
            continue
        try:
            r = repr(v)
        except Exception:  # noqa: BLE001 - an odd object's repr
            continue
        if 0 < len(r) <= 60 and r in msg:
            hits.append(k)
    return hits[0] if len(hits) == 1 else None


def _ctor_msg(e):
    msg = " ".join(str(e).split()) or type(e).__name__
    return f"bad argument: {type(e).__name__}: {msg}"


def _ctor_hint(init):
    import inspect
    try:
        sig = str(inspect.signature(init)).replace("(self, ", "(").replace("(self)", "()")
    except (TypeError, ValueError):  # pragma: no cover - builtins
        return None
    return f"the constructor takes {sig}"
