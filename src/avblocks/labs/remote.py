"""What a check sees of a student's file: proxies that call it remotely.

A check never holds the student's module. It is handed a
:class:`Submission`, whose attributes are the names the lab asks for
(``sub.MyUnicycle``, ``sub.wheels_to_cmd``): calling one sends a request
over the channel to the student's process and returns the answer, as
data. A class of the student's comes back as a :class:`RemoteBlock`, a
block of the grader's own that declares the same ports and states; its
``output``, ``derivative`` and ``update`` call the student's methods step
by step, so a closed loop is simulated by the grader's engine, not by
code the student could have patched.

The student's answers are checked on the way in: a list where an array
was expected, something that is not data, an output dict that lacks a
port, each fails the check with a message naming the function, the port
and (for a list) the line of the student's ``return``.
"""

from __future__ import annotations

import hashlib
import math
import time
import zlib

import numpy as np

from ..core.block import Block
from ..core.sample_times import INHERITED, Periodic
from . import wire
from .sandbox import SandboxError, StudentRaised

#: names a lab may not ask the student to define (they are the Submission's own)
RESERVED = frozenset({"rng", "seeded", "seed", "pick", "lab", "check", "deadline"})

_MAX_PORTS = 64
_MAX_ELEMENTS = 10 ** 6
_DTYPES = {"float64", "float32", "float16", "int64", "int32", "int16", "int8", "uint8",
           "uint16", "uint32", "uint64", "bool", "complex128", "complex64"}


class Failed(Exception):
    """A check's verdict: the student's code ran but gave the wrong answer
    (the message names the port, the case, what was expected and found)."""


def seed_for(*parts) -> int:
    """A seed in [0, 2**63) from any texts or numbers (SHA-256, so the same on
    every machine and Python)."""
    h = hashlib.sha256("\x1f".join(str(p) for p in parts).encode()).digest()
    return int.from_bytes(h[:8], "big") >> 1


class Submission:
    """The student's file, as a check sees it.

    Attributes named in the lab's ``names`` call the student's code
    remotely. Besides them:

    ``rng(k)``
        A NumPy generator for case ``k`` of this check: ``default_rng(k)``
        (the fixed cases of the lab's page) when the grader runs without a
        seed, otherwise one drawn from the seed, the check's name and ``k``.
    ``seeded``
        True when the grader draws per-student cases (``--seed``,
        ``--student``): a check then also draws the values it would
        otherwise fix (gains, goals).
    ``pick(fixed, draw)``
        ``fixed`` without a seed, else ``draw()``.
    """

    def __init__(self, runner, names, *, seed=None, check="", deadline=math.inf):
        self._runner = runner
        self._names = dict(names)
        self.seed = seed
        self.check = check
        self.deadline = deadline

    @property
    def seeded(self) -> bool:
        return self.seed is not None

    def rng(self, k=0) -> np.random.Generator:
        if self.seed is None:
            return np.random.default_rng(k)
        return np.random.default_rng([int(self.seed) % 2 ** 63, zlib.crc32(self.check.encode()),
                                      int(k)])

    def pick(self, fixed, draw):
        return fixed if self.seed is None else draw()

    def __getattr__(self, name):
        if name.startswith("_") or name not in self._names:
            raise AttributeError(f"the submission has no {name!r} (the lab asks for "
                                 f"{', '.join(self._names)})")
        kind = self._names[name]
        if kind == "class":
            return RemoteClass(self, name)
        if kind == "function":
            return RemoteFunction(self, name)
        raise Failed(f"`{name}` in the file is not a function or a class")

    def _request(self, op, **fields):
        return self._runner.request(op, self.deadline, **fields)


class RemoteFunction:
    """A function of the student's; calling it returns its result (arrays,
    numbers), or fails the check when the result is not data."""

    def __init__(self, sub, name):
        self._sub, self.name = sub, name

    def __call__(self, *args, **kwargs):
        ans = self._sub._request("call", name=self.name, args=list(args), kwargs=kwargs)
        return returned(ans, f"`{self.name}`", self._sub)


class RemoteClass:
    """A class of the student's; calling it constructs an instance in the
    student's process and returns its proxy (a :class:`RemoteBlock` for a
    block)."""

    def __init__(self, sub, name):
        self._sub, self.name = sub, name

    def __call__(self, *args, **kwargs):
        ans = self._sub._request("new", name=self.name, args=list(args), kwargs=kwargs)
        if not isinstance(ans, dict) or type(ans.get("obj")) is not int:
            raise Failed(f"constructing {self.name} gave no object")
        if ans.get("block") is None:
            raise Failed(f"{self.name} is not a block: it must subclass av.Block (as in the "
                         f"template)")
        return RemoteBlock(self._sub, ans["obj"], ans["block"], self.name)


def returned(ans, what, sub=None, expected="an array: build one array, e.g. "
                                            "xp.stack([...], axis=-1) or xp.asarray(...)"):
    """The value of a call's answer; :class:`Failed` when it is a list,
    a tuple or something that is not data (``expected`` says what should
    have come)."""
    if not isinstance(ans, dict) or "value" not in ans:
        raise Failed(f"{what} gave no value")
    value = ans["value"]
    lines = ans.get("returns") if isinstance(ans.get("returns"), list) else []
    if isinstance(value, (list, tuple)):
        kind = "a list" if isinstance(value, list) else "a tuple"
        raise Failed(f"{what} returned {kind}{_where_return(lines, sub)}, expected {expected}")
    _check_data(value, what, lines, sub)
    return value


def _where_return(lines, sub):
    lines = [x for x in lines if type(x) is int]
    if not lines:
        return ""
    name = sub._runner.display_name if sub is not None else "the file"
    if len(lines) == 1:
        return f" (line {lines[0]} of {name})"
    return f" (one of lines {', '.join(map(str, lines))} of {name})"


def _check_data(value, what, lines, sub):
    if isinstance(value, (list, tuple)):
        kind = "a list" if isinstance(value, list) else "a tuple"
        raise Failed(f"{what} returned {kind}{_where_return(lines, sub)}, expected an array: "
                     f"build one array, e.g. xp.stack([...], axis=-1) or xp.asarray(...)")
    if isinstance(value, wire.NotData):
        raise Failed(f"{what} returned {value.what}, not numbers")
    if isinstance(value, dict):
        for k, v in value.items():
            _check_data(v, f"{what} (its `{k}`)", lines, sub)


class RemoteBlock(Block):
    """A block of the grader's that stands for a block in the student's
    process: the same ports, states and sample time (validated), and
    ``output``/``derivative``/``update`` answered remotely, with the
    inputs sent read-only."""

    def __init__(self, sub, handle, desc, class_name):
        super().__init__()
        self._sub, self._handle, self.class_name = sub, handle, class_name
        try:
            self._declare(desc)
        except (TypeError, ValueError, KeyError, IndexError) as e:
            raise Failed(f"{class_name} declares ports or states the grader cannot use "
                         f"({type(e).__name__}: {str(e)[:120]})") from None

    def _declare(self, d):
        if not isinstance(d, dict):
            raise ValueError("no declarations")
        ins, outs = d["inputs"], d["outputs"]
        cst, dst = d["cstates"], d["dstates"]
        if sum(len(x) for x in (ins, outs, cst, dst)) > _MAX_PORTS:
            raise ValueError(f"more than {_MAX_PORTS} ports and states")
        for name, shape, dtype, ft, unit, agents in ins:
            self.declare_input(_ident(name), _shape(shape), _dtype(dtype), unit=_unit(unit),
                               agents=bool(agents), feedthrough=bool(ft))
        for name, shape, dtype, unit, agents in outs:
            self.declare_output(_ident(name), _shape(shape), _dtype(dtype), unit=_unit(unit),
                                agents=bool(agents))
        for name, init in cst:
            self.declare_continuous_state(_ident(name), _init(init))
        for name, init in dst:
            a = _init(init)
            self.declare_discrete_state(_ident(name), a, dtype=a.dtype)
        for name in d.get("random", []):
            if name in self._dstates:
                self._random.add(name)
        st = d.get("sample_time", ["continuous"])
        if st[0] == "periodic":
            period, offset = float(st[1]), float(st[2])
            if not (math.isfinite(period) and period > 0 and math.isfinite(offset)):
                raise ValueError("a sample period that is not a positive number")
            self.sample_time = Periodic(period, offset)
        elif st[0] == "inherited":
            self.sample_time = INHERITED
        self.update_uses_outputs = bool(d.get("update_uses_outputs", False))
        self._overrides = set(d.get("overrides", []))

    def __repr__(self):
        return super().__repr__().replace(type(self).__name__, self.class_name, 1)

    def _call(self, method, args, labels, klabels=None, kwargs=None):
        ans = self._sub._request("method", obj=self._handle, name=method, args=list(args),
                                 kwargs=kwargs or {}, labels=labels, klabels=klabels or {})
        what = f"`{method}` of {self.class_name}"
        ports = self._outputs if method == "output" else \
            self._cstates if method == "derivative" else self._dstates
        value = returned(ans, what, self._sub, expected="a dict {" + ", ".join(
            f"'{k}': array" for k in ports) + "}")
        if not isinstance(value, dict):
            raise Failed(f"{what} returned {_kind(value)}, expected a dict {{name: array}}")
        return {k: _array(v, f"{what} (its `{k}`)") for k, v in value.items()}

    def output(self, t, x, u, xp):
        if "output" not in self._overrides and not self._outputs:
            return {}
        return self._call("output", (t, x, u, xp), [None, "state", "input", None])

    def derivative(self, t, x, u, xp):
        return self._call("derivative", (t, x, u, xp), [None, "state", "input", None])

    def update(self, t, x, u, xp, y=None):
        if self.update_uses_outputs:
            return self._call("update", (t, x, u, xp), [None, "state", "input", None],
                              {"y": "output"}, {"y": y})
        return self._call("update", (t, x, u, xp), [None, "state", "input", None])


def _kind(v) -> str:
    if isinstance(v, np.ndarray):
        return f"an array of shape {v.shape}"
    if isinstance(v, wire.NotData):
        return v.what
    return f"a {type(v).__name__}"


def _array(v, what):
    if isinstance(v, np.ndarray):
        return v
    if isinstance(v, (bool, int, float, complex)):
        return np.asarray(v)
    raise Failed(f"{what} is {_kind(v)}, not an array")


def _ident(name):
    if not (isinstance(name, str) and name.isidentifier() and len(name) <= 60):
        raise ValueError(f"a port name that is not an identifier: {str(name)[:40]!r}")
    return name


def _shape(shape):
    if shape is None:
        return None
    if not (isinstance(shape, list) and len(shape) <= 8
            and all(type(s) is int and 0 <= s <= _MAX_ELEMENTS for s in shape)):
        raise ValueError(f"a port shape that is not a few whole numbers: {str(shape)[:40]}")
    if math.prod(shape) > _MAX_ELEMENTS:
        raise ValueError(f"a port of {math.prod(shape)} elements (at most {_MAX_ELEMENTS})")
    return tuple(shape)


def _dtype(dt):
    if dt not in _DTYPES:
        raise ValueError(f"a port dtype the grader does not use: {str(dt)[:20]!r}")
    return dt


def _unit(u):
    return u[:60] if isinstance(u, str) else ""


def _init(v):
    if isinstance(v, (bool, int, float)):
        v = np.asarray(v)
    if not isinstance(v, np.ndarray) or v.size > _MAX_ELEMENTS:
        raise ValueError("an initial state that is not an array")
    return np.array(v)


def remaining(deadline) -> float:
    """Seconds left until ``deadline`` (a monotonic time)."""
    return deadline - time.monotonic()


__all__ = ["Failed", "RESERVED", "RemoteBlock", "RemoteClass", "RemoteFunction",
           "SandboxError", "StudentRaised", "Submission", "returned", "seed_for"]
