"""The grader's data-only channel: JSON framing plus raw array bytes.

Everything that passes between the grader and the process running a
student's code is one of these messages, in both directions; nothing is
pickled and nothing names code to run. A message (a *frame*) is::

    b"AVL1"  header length (4 bytes, big-endian)  header (UTF-8 JSON)  blobs

The header is ``{"v": value, "b": [n0, n1, ...]}``: the value, and the byte
lengths of the blobs that follow it, in order. A value is JSON (``null``,
booleans, numbers, strings, arrays) except for objects, each of which has
exactly one of these keys:

=================================  ==============================================
``{"$a": [i, dtype, shape]}``      a NumPy array: blob ``i`` holds its bytes, C order;
                                   ``dtype`` one of :data:`DTYPES` (little-endian)
``{"$d": [[key, value], ...]}``    a dict with string keys
``{"$t": [...]}``                  a tuple
``{"$f": "nan" | "inf" | "-inf"}`` a float that JSON cannot write
``{"$o": "what it was"}``          something that is not data (a function, a class
                                   instance), sent as its type name only
``{"$x": "numpy"}``                the array namespace ``xp`` (grader to child only)
=================================  ==============================================

Decoding checks every field against :class:`Limits` (size of a message,
of the header, nesting depth, number of values, string length, array
dimensions) and builds arrays with :func:`numpy.frombuffer` from the
allowed dtypes only, so they come out read-only. Anything else is a
:class:`WireError` with a message that says what was wrong; it never
executes anything.
"""

from __future__ import annotations

import json
import math
import struct
from dataclasses import dataclass

import numpy as np

MAGIC = b"AVL1"
_HEAD = struct.Struct(">4sI")

#: the array dtypes that may cross (``numpy.dtype.str``, little-endian)
DTYPES = frozenset({"|b1", "|i1", "<i2", "<i4", "<i8", "|u1", "<u2", "<u4", "<u8",
                    "<f2", "<f4", "<f8", "<c8", "<c16"})

#: the array namespace's marker (the grader sends it where a function takes ``xp``)
XP = {"$x": "numpy"}


class WireError(Exception):
    """A message that is not what the channel carries (malformed, too large,
    too deep, an unknown marker); the text says which."""


@dataclass(frozen=True)
class Limits:
    """What one message may hold.

    Attributes
    ----------
    message_bytes : int
        Header plus blobs of one message.
    header_bytes : int
        The JSON header of one message.
    depth : int
        Nesting of lists, tuples and dicts.
    values : int
        Values in one message (numbers, strings, arrays, containers).
    string_chars : int
        One string.
    ndim : int
        Dimensions of one array.
    """

    message_bytes: int = 16 * 2 ** 20
    header_bytes: int = 2 ** 20
    depth: int = 32
    values: int = 200_000
    string_chars: int = 200_000
    ndim: int = 8


DEFAULT = Limits()


# ------------------------------------------------------------------ encoding
def encode(value, limits=DEFAULT, *, allow_xp=False) -> bytes:
    """One frame holding ``value``. Values that are not data become
    ``{"$o": type name}``; :class:`WireError` when the result would break
    ``limits`` (too large, too deep)."""
    blobs: list = []
    count = [0]
    total = [0]

    def enc(v, depth):
        count[0] += 1
        if count[0] > limits.values:
            raise WireError(f"more than {limits.values} values")
        if depth > limits.depth:
            raise WireError(f"nested deeper than {limits.depth} levels")
        t = type(v)
        if t is float:                      # the common cases first, by exact type
            return v if v - v == 0.0 else {"$f": "nan" if v != v else (
                "inf" if v > 0 else "-inf")}
        if t is np.ndarray:
            return array(v)
        if t is dict:
            return mapping(v, depth)
        if t is str:
            if len(v) > limits.string_chars:
                return {"$o": f"a string of {len(v)} characters"}
            return v
        if v is None or t is bool:
            return v
        if t is int:
            return v if -2 ** 63 <= v < 2 ** 63 else {"$o": "an integer too large for int64"}
        if t is list:
            return [enc(x, depth + 1) for x in v]
        if t is tuple:
            return {"$t": [enc(x, depth + 1) for x in v]}
        if allow_xp and v is np:
            return XP
        if isinstance(v, (np.ndarray, np.generic, complex)):
            return array(np.asarray(v))
        if isinstance(v, bool):
            return bool(v)
        if isinstance(v, int):
            return enc(int(v), depth)
        if isinstance(v, float):
            return enc(float(v), depth)
        if isinstance(v, str):
            return enc(str(v), depth)
        if isinstance(v, dict):
            return mapping(v, depth)
        if isinstance(v, (list, tuple)):
            return enc(list(v) if isinstance(v, list) else tuple(v), depth)
        try:
            name = type(v).__name__
        except Exception:                 # noqa: BLE001 - a hostile type
            name = "object"
        return {"$o": f"a {str(name)[:60]} object"}

    def mapping(v, depth):
        out = []
        for k, x in v.items():
            if type(k) is not str:
                return {"$o": "a dict whose keys are not all strings"}
            out.append([k, enc(x, depth + 1)])
        return {"$d": out}

    def array(a):
        if a.dtype.byteorder == ">":
            a = a.astype(a.dtype.newbyteorder("<"))
        dt = a.dtype.str
        if dt not in DTYPES:
            return {"$o": f"an array of dtype {a.dtype}"}
        if a.ndim > limits.ndim:
            raise WireError(f"an array of {a.ndim} dimensions (at most {limits.ndim})")
        total[0] += a.nbytes
        if total[0] > limits.message_bytes:
            raise WireError(f"arrays of {total[0]} bytes, over the limit of "
                            f"{limits.message_bytes} bytes per message")
        blobs.append(a.tobytes())
        return {"$a": [len(blobs) - 1, dt, list(a.shape)]}

    head = json.dumps({"v": enc(value, 0), "b": [len(b) for b in blobs]},
                      allow_nan=False, separators=(",", ":")).encode()
    if len(head) > limits.header_bytes:
        raise WireError(f"a header of {len(head)} bytes (at most {limits.header_bytes})")
    if len(head) + total[0] > limits.message_bytes:
        raise WireError(f"a message of {len(head) + total[0]} bytes, over the limit of "
                        f"{limits.message_bytes}")
    return b"".join([_HEAD.pack(MAGIC, len(head)), head, *blobs])


# ------------------------------------------------------------------ decoding
def read(read_exact, limits=DEFAULT, *, allow_xp=False):
    """Read one frame with ``read_exact(n) -> bytes`` (exactly ``n`` bytes,
    :class:`EOFError` at the end) and decode it. Returns ``(value, nbytes)``."""
    head = read_exact(_HEAD.size)
    magic, n = _HEAD.unpack(head)
    if magic != MAGIC:
        raise WireError(f"a message that does not start with {MAGIC!r} (found "
                        f"{bytes(magic)!r}): not the grader's channel format")
    if n > limits.header_bytes:
        raise WireError(f"a header of {n} bytes (at most {limits.header_bytes})")
    raw = read_exact(n)
    try:
        doc = json.loads(raw.decode("utf-8"), parse_constant=_no_constant)
    except (UnicodeDecodeError, ValueError, RecursionError) as e:
        raise WireError(f"a header that is not JSON ({type(e).__name__}: "
                        f"{str(e)[:80]})") from None
    if not isinstance(doc, dict) or set(doc) != {"v", "b"} or not isinstance(doc["b"], list):
        raise WireError("a header that is not {\"v\": value, \"b\": [blob sizes]}")
    sizes = doc["b"]
    if len(sizes) > limits.values or not all(type(s) is int and s >= 0 for s in sizes):
        raise WireError("blob sizes that are not whole numbers >= 0")
    if n + sum(sizes) > limits.message_bytes:
        raise WireError(f"a message of {n + sum(sizes)} bytes, over the limit of "
                        f"{limits.message_bytes} bytes")
    blobs = [read_exact(s) for s in sizes]
    return decode(doc["v"], blobs, limits, allow_xp=allow_xp), _HEAD.size + n + sum(sizes)


def _no_constant(name):
    raise ValueError(f"{name} is not JSON")


def decode(tree, blobs, limits=DEFAULT, *, allow_xp=False):
    """The value a decoded header's ``"v"`` stands for."""
    count = [0]

    def dec(v, depth):
        count[0] += 1
        if count[0] > limits.values:
            raise WireError(f"more than {limits.values} values in one message")
        if depth > limits.depth:
            raise WireError(f"values nested deeper than {limits.depth} levels")
        t = type(v)
        if t is float or t is int or t is bool or v is None:
            return v
        if t is str:
            if len(v) > limits.string_chars:
                raise WireError(f"a string of {len(v)} characters")
            return v
        if t is list:
            return [dec(x, depth + 1) for x in v]
        if t is not dict or len(v) != 1:
            raise WireError("an object that is not one of the channel's markers")
        (key, body), = v.items()
        if key == "$a":
            return _array(body, blobs, limits)
        if key == "$d" and type(body) is list:
            out = {}
            for pair in body:
                if not (type(pair) is list and len(pair) == 2 and type(pair[0]) is str):
                    raise WireError("a dict entry that is not [key, value]")
                if len(pair[0]) > 200:
                    raise WireError("a dict key longer than 200 characters")
                out[pair[0]] = dec(pair[1], depth + 1)
            return out
        if key == "$t" and type(body) is list:
            return tuple(dec(x, depth + 1) for x in body)
        if key == "$f" and body in ("nan", "inf", "-inf"):
            return float(body)
        if key == "$o" and type(body) is str:
            return NotData(body[:100])
        if key == "$x" and allow_xp and body == "numpy":
            return np
        raise WireError(f"an unknown or misused marker {str(key)[:20]!r}")

    return dec(tree, 0)


def _array(body, blobs, limits):
    if not (isinstance(body, list) and len(body) == 3 and type(body[0]) is int
            and isinstance(body[1], str) and isinstance(body[2], list)):
        raise WireError("an array marker that is not [blob, dtype, shape]")
    i, dt, shape = body
    if not 0 <= i < len(blobs):
        raise WireError(f"an array marker naming blob {i} of {len(blobs)}")
    if dt not in DTYPES:
        raise WireError(f"an array of dtype {dt[:20]!r}, which the channel does not carry")
    if len(shape) > limits.ndim or not all(type(s) is int and 0 <= s < 2 ** 40 for s in shape):
        raise WireError("an array shape that is not a few whole numbers >= 0")
    dtype = np.dtype(dt)
    size = math.prod(shape) * dtype.itemsize
    if size != len(blobs[i]):
        raise WireError(f"an array of shape {tuple(shape)} and dtype {dt} needs {size} "
                        f"bytes, its blob has {len(blobs[i])}")
    return np.frombuffer(blobs[i], dtype=dtype).reshape(shape)


class NotData:
    """What arrives for something the other side could not send as data
    (``{"$o": ...}``): a function, a class instance, an array of objects."""

    __slots__ = ("what",)

    def __init__(self, what):
        self.what = what

    def __repr__(self):
        return f"<not data: {self.what}>"

    def __eq__(self, other):
        return isinstance(other, NotData) and other.what == self.what

    __hash__ = None
