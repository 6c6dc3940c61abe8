"""Functional random numbers from explicit keys.

A key is a ``uint32`` array of shape ``(2,)``, the same layout JAX uses for
its raw PRNG keys, so a block's random draws trace under JAX unchanged. Under
NumPy a key seeds a counter-based Philox generator; nothing global is touched
and the same key always gives the same numbers.

Typical use inside a block's ``update``::

    key, sub = rng.split(x["key"], xp)
    step = rng.normal(sub, (n, 2), xp)
    return {"key": key, ...}
"""

from __future__ import annotations

import zlib

import numpy as np


def key(seed: int, stream: str | int = 0) -> np.ndarray:
    """A key from an integer seed and an optional stream name or number."""
    if isinstance(stream, str):
        stream = zlib.crc32(stream.encode())
    ss = np.random.SeedSequence([int(seed) & 0xFFFFFFFFFFFFFFFF, int(stream)])
    return ss.generate_state(2, dtype=np.uint32)


def _is_numpy(xp) -> bool:
    return getattr(xp, "__name__", "numpy") == "numpy"


def _gen(k) -> np.random.Generator:
    k = np.asarray(k, dtype=np.uint32)
    return np.random.Generator(np.random.Philox(key=(int(k[0]) << 32) | int(k[1])))


def split(k, xp=np, num: int = 2):
    """``num`` new independent keys from ``k`` (returned as a tuple)."""
    if _is_numpy(xp):
        ks = _gen(k).integers(0, 2**32, size=(num, 2), dtype=np.uint32)
        return tuple(ks[i] for i in range(num))
    import jax
    ks = jax.random.split(k, num)
    return tuple(ks[i] for i in range(num))


def uniform(k, shape, xp=np, low=0.0, high=1.0):
    """Uniform samples on ``[low, high)``."""
    if _is_numpy(xp):
        return _gen(k).uniform(low, high, size=shape)
    import jax
    return jax.random.uniform(k, shape, minval=low, maxval=high, dtype=float)


def normal(k, shape, xp=np, mean=0.0, std=1.0):
    """Normal samples with the given mean and standard deviation."""
    if _is_numpy(xp):
        return _gen(k).normal(mean, std, size=shape)
    import jax
    return mean + std * jax.random.normal(k, shape, dtype=float)


def exponential(k, shape, xp=np, scale=1.0):
    """Exponential samples with the given mean (``scale``)."""
    if _is_numpy(xp):
        return _gen(k).exponential(scale, size=shape)
    import jax
    return scale * jax.random.exponential(k, shape, dtype=float)
