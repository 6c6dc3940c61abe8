"""Functional random numbers from explicit keys: one stream for both engines.

A key is a ``uint32`` array of shape ``(2,)``. Every draw is a pure function
of its key, computed by the counter-based block cipher Threefry-2x32 with
20 rounds (Salmon, Moraes, Dror and Shaw, "Parallel random numbers: as
easy as 1, 2, 3", SC 2011), written with the array namespace ``xp`` in
``uint32`` arithmetic (additions wrap modulo 2^32, rotations by shifts). So
the NumPy engine and the compiled engine (``jax.jit``, ``vmap``) produce the
same bits for the same key; uniforms on [0, 1) are bit-identical, and the
shaped floats agree to the accuracy of the elementary functions of each
engine (``log1p``, ``sqrt``, ``cos``; XLA may also fuse multiply-adds):
within 1e-13 relative in the tests.

Stream layout (all counters are pairs of ``uint32`` words ``(c0, c1)``)

- ``split(k, num)``: key ``i`` is the cipher of ``(i, 0xFFFFFFFF)``.
- sample ``i`` of a draw of ``shape`` (row-major) uses the block
  ``(i, 0)``: its two output words give 53 random bits (float64: ``u =
  ((w0 >> 5) 2^26 + (w1 >> 6)) 2^-53`` in ``[0, 1)``) or 24 bits (float32:
  ``u = (w0 >> 8) 2^-24``).
- ``normal`` uses Box-Muller on blocks ``(i, 0)`` and ``(i, 1)``:
  ``z = sqrt(-2 log(1 - u1)) cos(2 pi u2)``.
- ``exponential``: ``-log(1 - u)``; ``bernoulli``: ``u < p``;
  ``randint``: ``low + floor(u (high - low))`` (bias below 2^-53 (high -
  low)).

Typical use inside a block's ``update``::

    key, sub = rng.split(x["key"], xp)
    step = rng.normal(sub, (n, 2), xp)
    return {"key": key, ...}
"""

from __future__ import annotations

import math
import zlib

import numpy as np

_ROT = ((13, 15, 26, 6), (17, 29, 16, 24))
_PARITY = 0x1BD11BDA
_SPLIT_WORD = 0xFFFFFFFF


def key(seed: int, stream: str | int = 0) -> np.ndarray:
    """A key from an integer seed and an optional stream name or number (host side)."""
    if isinstance(stream, str):
        stream = zlib.crc32(stream.encode())
    ss = np.random.SeedSequence([int(seed) & 0xFFFFFFFFFFFFFFFF, int(stream)])
    return ss.generate_state(2, dtype=np.uint32)


def _u32(v, xp):
    return xp.asarray(v, dtype=np.uint32)


def _rotl(v, r):
    # Python-int shift counts keep the uint32 dtype (NumPy >= 2 and JAX alike)
    return (v << r) | (v >> (32 - r))


def threefry2x32(k0, k1, x0, x1, xp=np):
    """Threefry-2x32, 20 rounds: the cipher of counter ``(x0, x1)`` under key
    ``(k0, k1)``; all ``uint32`` (broadcast elementwise). Returns ``(y0, y1)``."""
    k0, k1, x0, x1 = (_u32(a, xp) for a in (k0, k1, x0, x1))
    if xp is np and np.broadcast_shapes(x0.shape, x1.shape, k0.shape, k1.shape):
        return _threefry_np(k0, k1, x0, x1)
    with np.errstate(over="ignore"):            # wrapping is the point
        ks = (k0, k1, k0 ^ k1 ^ _u32(_PARITY, xp))
        x0 = x0 + ks[0]
        x1 = x1 + ks[1]
        for i in range(5):                      # 5 groups of 4 rounds
            for r in _ROT[i % 2]:
                x0 = x0 + x1
                x1 = _rotl(x1, r) ^ x0
            x0 = x0 + ks[(i + 1) % 3]
            x1 = x1 + (ks[(i + 2) % 3] + _u32(i + 1, xp))
    return x0, x1


def _threefry_np(k0, k1, x0, x1):
    """The same rounds with NumPy ufuncs writing into two fresh work arrays
    (no input is modified; about 2x faster than the expression form)."""
    ks = (k0, k1, k0 ^ k1 ^ np.uint32(_PARITY))
    shape = np.broadcast_shapes(x0.shape, x1.shape, k0.shape, k1.shape)
    a = np.add(np.broadcast_to(x0, shape), ks[0], dtype=np.uint32)     # new arrays
    b = np.add(np.broadcast_to(x1, shape), ks[1], dtype=np.uint32)
    tmp = np.empty(shape, np.uint32)
    for i in range(5):
        for r in _ROT[i % 2]:
            np.add(a, b, out=a)
            np.left_shift(b, r, out=tmp)
            np.right_shift(b, 32 - r, out=b)
            np.bitwise_or(b, tmp, out=b)
            np.bitwise_xor(b, a, out=b)
        np.add(a, ks[(i + 1) % 3], out=a)
        np.add(b, ks[(i + 2) % 3] + np.uint32(i + 1), out=b)
    return a, b


def _blocks(k, n, word, xp):
    k = _u32(k, xp)
    c = xp.arange(n, dtype=np.uint32)
    return threefry2x32(k[..., 0], k[..., 1], c, _u32(word, xp), xp)


def split(k, xp=np, num: int = 2):
    """``num`` new independent keys from ``k`` (returned as a tuple of (2,) keys)."""
    y0, y1 = _blocks(k, num, _SPLIT_WORD, xp)
    ks = xp.stack([y0, y1], axis=-1)
    return tuple(ks[i] for i in range(num))


def bits(k, shape, xp=np, word=0):
    """Two ``uint32`` words per sample, each of ``shape``: the raw stream."""
    shape = (int(shape),) if np.ndim(shape) == 0 else tuple(int(s) for s in shape)
    n = math.prod(shape)
    y0, y1 = _blocks(k, n, word, xp)
    return y0.reshape(shape), y1.reshape(shape)


def _float_dtype(xp):
    return xp.asarray(0.0).dtype


def _unit(k, shape, xp, word=0):
    """Uniform on [0, 1) in the namespace's float type (53 or 24 random bits)."""
    y0, y1 = bits(k, shape, xp, word)
    return _to_unit(y0, y1, xp)


def _to_unit(y0, y1, xp):
    ft = _float_dtype(xp)
    if ft == np.float64:
        hi = (y0 >> _u32(5, xp)).astype(np.float64)
        lo = (y1 >> _u32(6, xp)).astype(np.float64)
        return (hi * 67108864.0 + lo) * (2.0 ** -53)
    return (y0 >> _u32(8, xp)).astype(ft) * ft.type(2.0 ** -24)


def uniform_at(k, c0, c1, xp=np):
    """Uniform on [0, 1) at explicit counters ``(c0, c1)`` (integer arrays,
    broadcast together, values in ``[0, 2^32)``).

    The draw for a counter does not depend on which other counters are asked
    for or in what layout: e.g. a link ``i -> j`` gets ``uniform_at(k, i, j)``
    whatever the shape of the neighbour table it sits in. Counters ``(i, 0)``
    and ``(i, 1)`` are the ones :func:`uniform` and :func:`normal` use: take
    a key for one purpose only.
    """
    k = _u32(k, xp)
    c0 = xp.asarray(c0).astype(np.uint32)
    c1 = xp.asarray(c1).astype(np.uint32)
    y0, y1 = threefry2x32(k[..., 0], k[..., 1], c0, c1, xp)
    return _to_unit(y0, y1, xp)


def uniform(k, shape, xp=np, low=0.0, high=1.0):
    """Uniform samples on ``[low, high)``."""
    u = _unit(k, shape, xp)
    return low + (high - low) * u


def normal(k, shape, xp=np, mean=0.0, std=1.0):
    """Normal samples with the given mean and standard deviation (Box-Muller)."""
    u1 = _unit(k, shape, xp, 0)
    u2 = _unit(k, shape, xp, 1)
    z = xp.sqrt(-2.0 * xp.log1p(-u1)) * xp.cos((2.0 * np.pi) * u2)
    return mean + std * z


def exponential(k, shape, xp=np, scale=1.0):
    """Exponential samples with the given mean (``scale``)."""
    return -scale * xp.log1p(-_unit(k, shape, xp))


def bernoulli(k, shape, xp=np, p=0.5):
    """Booleans, true with probability ``p`` (``u < p``)."""
    return _unit(k, shape, xp) < p


def randint(k, shape, xp=np, low=0, high=2):
    """Integers uniform on ``[low, high)`` (``int64``, or the traced default int)."""
    u = _unit(k, shape, xp)
    v = xp.floor(u * (high - low))
    return (low + v).astype(xp.asarray(0).dtype)
