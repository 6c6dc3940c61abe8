"""What a compiled run hands back, checked: :func:`check_finite` (NaN/inf in
the logged signals or the final state raise :class:`SimulationError` with
the results attached).

A large run's results are checked where they are (:func:`finite_on_device`:
one flag per array comes back) and its final state is read from the device
only when asked for (:class:`FinalStates`): at 10^7 agents the logs and
the final state are hundreds of MB, and scanning them on the host after
copying them there is a fixed cost of every call."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..errors import SimulationError

#: a run whose logs and final state hold at least this many bytes is
#: checked on the device and keeps its final state there until read
LARGE_BYTES = 16 * 2**20


def large(logs, finals) -> bool:
    """Whether the arrays of a run's logs and final state pass :data:`LARGE_BYTES`."""
    total = 0
    for a in logs:
        total += a.nbytes
    for a in finals:
        total += a.nbytes
    return total >= LARGE_BYTES


_FLAGS: dict = {}


def finite_on_device(arrays):
    """``[bool]``: whether each float array (a JAX array, where it lives) is
    all finite, computed there by one small compiled program (a flag per
    array comes back; non-float arrays count as finite)."""
    from . import _jax
    from .devices import host
    jax = _jax.jax()
    floats = [a for a in arrays if np.dtype(a.dtype).kind == "f"]
    if not floats:
        return []
    fn = _FLAGS.get("fn")
    if fn is None:
        jnp = jax.numpy
        fn = _FLAGS["fn"] = jax.jit(lambda xs: jnp.stack([jnp.all(jnp.isfinite(x))
                                                          for x in xs]))
    return [bool(v) for v in host(fn(floats))]


class FinalStates(Mapping):
    """``{"block.state": array}`` of a run's final state, each read from
    the device (a NumPy array) the first time it is asked for."""

    def __init__(self, values):
        self._values = dict(values)
        self._host = {}

    def __getitem__(self, key):
        got = self._host.get(key)
        if got is None:
            from .devices import host
            got = self._host[key] = host(self._values[key])
        return got

    def __iter__(self):
        return iter(self._values)

    def __len__(self):
        return len(self._values)

    def __repr__(self):
        return f"FinalStates({sorted(self._values)})"


def final_states(values, on_device=False):
    """The final-state mapping of a run: a plain dict of host arrays, or a
    :class:`FinalStates` when they live on a device (``on_device``)."""
    return FinalStates(values) if on_device else values


def check_finite(res, finite=None):
    """Raise SimulationError (results attached) if a logged float signal or
    the final state is NaN/inf: the first sample and signal that is.
    ``finite``: flags from :func:`finite_on_device` of the same arrays; all
    True means nothing to look for (no scan on the host)."""
    if finite is not None and all(finite):
        return
    axis0 = 1 if res.runs is not None else 0
    first, where = None, None
    for k, v in res.data.items():
        if v.dtype.kind != "f" or np.isfinite(v).all():
            continue
        bad = ~np.isfinite(v)
        per_t = bad.reshape(*v.shape[:axis0 + 1], -1).any(-1)
        if axis0:
            per_t = per_t.any(0)
        j = int(np.argmax(per_t))
        if first is None or j < first:
            first, where = j, k
    if where is None:
        for k, v in res.final_state.items():
            if np.asarray(v).dtype.kind == "f" and not np.isfinite(v).all():
                b, _, nm = k.rpartition(".")
                raise SimulationError(
                    f"state '{nm}' is NaN or infinite at the end of the run",
                    block=b, results=res,
                    hint="log more signals (or check_finite=False) to find where; the "
                         "NumPy backend stops at the first step and names the block")
        return
    b, _, port = where.rpartition(".")
    runs = ""
    if res.runs is not None:
        v = res.data[where]
        bad = ~np.isfinite(v.reshape(v.shape[0], -1)).all(-1)
        runs = f" in run(s) {np.flatnonzero(bad)[:10].tolist()}"
    raise SimulationError(f"logged output is NaN or infinite{runs}", block=b, port=port,
                          time=float(res.t[first]), results=res,
                          hint="the NumPy backend stops at the first bad step and "
                               "names the block that produced it")
