"""``check_block``: a conformance checker users run on their own blocks.

>>> import numpy as np, avblocks as av
>>> report = av.core.check.check_block(lambda n: av.vehicles.Unicycle(pose0=np.zeros((n, 3))))
>>> report.ok
True

It builds the block for several agent counts and checks, for each:
declared shapes are concrete; ``output``, ``derivative`` and ``update``
return exactly the declared ports/states with the declared shapes and
dtypes; per-agent ports have N on their leading axis; inputs and states are
not mutated; two calls with the same values give the same result (seeded
determinism); finite inputs give finite outputs; ``output`` only needs the
inputs declared direct-feedthrough.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import rng as _rng
from .block import Block
from .errors import AvError


@dataclass
class CheckReport:
    """What :func:`check_block` found. ``ok`` is true when nothing failed."""

    block: str
    checked_n: list = field(default_factory=list)
    failures: list = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.failures

    def __str__(self):
        head = f"check_block({self.block}) at N={self.checked_n}: "
        if self.ok:
            return head + "all checks passed"
        return head + f"{len(self.failures)} failure(s)\n  - " + "\n  - ".join(self.failures)


def _sample(port, n_gen, gen):
    shape = port.shape
    kind = np.dtype(port.dtype).kind
    if kind == "b":
        return gen.random(shape) < 0.5
    if kind in "iu":
        return np.zeros(shape, dtype=port.dtype)
    return gen.normal(size=shape).astype(port.dtype)


def _copy(d):
    return {k: np.array(v, copy=True) for k, v in d.items()}


def _same(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and np.array_equal(a, b, equal_nan=a.dtype.kind in "fc")


def check_block(factory, ns=(1, 7), *, inputs=None, seed=0, raise_on_failure=True):
    """Check a block against the block contract.

    Parameters
    ----------
    factory : callable ``n -> Block`` or a Block
        Builds the block for ``n`` agents. A Block instance is checked as is.
    ns : tuple of int
        Agent counts to try (with a factory).
    inputs : callable ``(n, block) -> {name: array}``, optional
        Input values to use (default: standard-normal floats, random bools,
        zero integers, with the declared shapes).
    seed : int
    raise_on_failure : bool
        Raise :class:`AvError` listing every failure (default) or only
        return the report.
    """
    if isinstance(factory, Block):
        blocks = [(getattr(factory, "n", None), factory)]
    else:
        blocks = [(n, factory(n)) for n in ns]
    report = CheckReport(type(blocks[0][1]).__name__)
    for n, b in blocks:
        report.checked_n.append(n)
        _check_one(b, n, inputs, seed, report.failures)
    if raise_on_failure and not report.ok:
        raise AvError(str(report))
    return report


def _check_one(b, n, inputs, seed, fail):
    name = f"{type(b).__name__}[N={n}]"
    if not isinstance(b, Block):
        fail.append(f"{name}: not a Block")
        return
    for kind, ports in (("input", b._inputs), ("output", b._outputs)):
        for p in ports.values():
            if p.shape is None:
                fail.append(f"{name}: {kind} '{p.name}' has no shape; give it one or "
                            "pass concrete inputs through a diagram")
                return
            if n is not None and p.agents and p.shape and p.shape[0] != n:
                fail.append(f"{name}: {kind} '{p.name}' leading axis {p.shape[0]} "
                            f"is not the agent count {n}")
    gen = np.random.default_rng(seed)
    u = inputs(n, b) if inputs is not None else {
        k: _sample(p, n, gen) for k, p in b._inputs.items()}
    missing = set(b._inputs) - set(u)
    if missing:
        fail.append(f"{name}: inputs missing from the sample: {sorted(missing)}")
        return
    x = b.initial_state()
    for r in b._random:
        x[r] = _rng.key(seed, r)
    u0, x0 = _copy(u), _copy(x)
    u_ft = {k: v for k, v in u.items() if k in b.feedthrough}
    calls = [("output", b._outputs, lambda: b.output(0.3, x, u_ft, np))]
    if b._cstates:
        calls.append(("derivative", b._cstates, lambda: b.derivative(0.3, x, u, np)))
    if b._dstates:
        if b.update_uses_outputs:
            def upd():
                y = b.output(0.3, x, u_ft, np)
                if not isinstance(y, dict):
                    y = {next(iter(b._outputs)): y}
                return b.update(0.3, x, u, np, y=y)
        else:
            def upd():
                return b.update(0.3, x, u, np)
        calls.append(("update", b._dstates, upd))
    for fname, decl, call in calls:
        try:
            r1 = call()
            r2 = call()
        except Exception as e:  # noqa: BLE001 - report, do not crash the checker
            hint = " (output() only receives feedthrough inputs)" if (
                fname == "output" and isinstance(e, KeyError)) else ""
            fail.append(f"{name}: {fname}() raised {type(e).__name__}: {e}{hint}")
            continue
        if fname == "output" and not isinstance(r1, dict) and len(decl) == 1:
            r1, r2 = {next(iter(decl)): r1}, {next(iter(decl)): r2}
        if not isinstance(r1, dict):
            fail.append(f"{name}: {fname}() must return a dict, got {type(r1).__name__}")
            continue
        keys = set(r1)
        want = set(decl)
        if fname == "update":
            if not keys <= want:
                fail.append(f"{name}: update() returned unknown states {sorted(keys - want)}")
        elif keys != want:
            fail.append(f"{name}: {fname}() returned {sorted(keys)}, declared {sorted(want)}")
        for k in keys & want:
            a = np.asarray(r1[k])
            p = decl[k]
            if a.shape != p.shape:
                fail.append(f"{name}: {fname}() '{k}' has shape {a.shape}, declared {p.shape}")
            if fname != "derivative" and a.dtype.kind != np.dtype(p.dtype).kind:
                fail.append(f"{name}: {fname}() '{k}' has dtype {a.dtype}, declared {p.dtype}")
            if not _same(r1[k], r2[k]):
                fail.append(f"{name}: {fname}() '{k}' differs between two identical calls "
                            "(hidden state or unseeded randomness)")
            if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
                fail.append(f"{name}: {fname}() '{k}' is not finite for finite inputs")
    for k in u0:
        if not _same(u0[k], u[k]):
            fail.append(f"{name}: input '{k}' was modified in place")
    for k in x0:
        if not _same(x0[k], x[k]):
            fail.append(f"{name}: state '{k}' was modified in place")
