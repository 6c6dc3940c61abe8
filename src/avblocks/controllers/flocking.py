r"""Flocking of double integrators: Olfati-Saber (2006), Algorithm 1 (+ gamma).

Equations (R. Olfati-Saber, "Flocking for multi-agent dynamic systems:
algorithms and theory", IEEE TAC 51(3), 2006, Sections II and IV)
-------------------------------------------------------------------
sigma-norm and its gradient, ``eps > 0``:

    ||z||_s = (sqrt(1 + eps |z|^2) - 1) / eps,   sigma_eps(z) = z / sqrt(1 + eps |z|^2)

bump function, ``h in (0, 1)``:

    rho_h(s) = 1 on [0, h),  (1 + cos(pi (s - h) / (1 - h))) / 2 on [h, 1],  0 else

action function with ``r_a = ||r||_s``, ``d_a = ||d||_s``:

    phi(s) = ((a + b) sigma_1(s + c) + (a - b)) / 2,  sigma_1(s) = s / sqrt(1 + s^2),
    c = |a - b| / sqrt(4 a b),   phi_a(s) = rho_h(s / r_a) phi(s - d_a)

Algorithm 1 (alpha-lattice), eq. (23), for agents with ``q' = p, p' = u``:

    u_i^a = c1 sum_{j in N_i} phi_a(||q_j - q_i||_s) sigma_eps(q_j - q_i)
          + c2 sum_{j in N_i} rho_h(||q_j - q_i||_s / r_a) (p_j - p_i)

The optional navigational feedback (gamma agent, Algorithm 2, eq. (24)) adds

    u_i^g = -c1_g (q_i - q_r) - c2_g (p_i - p_r)

for a gamma agent moving at constant velocity, ``q_r(t) = target +
target_velocity t``, ``p_r = target_velocity`` (``gamma=True``). ``N_i`` are the agents
within the interaction range ``r`` (terms vanish beyond ``r`` through
``rho_h``, so a superset of neighbours is harmless). Defaults follow the
paper's simulations: ``eps = 0.1, a = b = 5, h = 0.2, r = 1.2 d``.
Without gamma, Algorithm 1 may fragment; with gamma it forms a flock.
"""

from __future__ import annotations

import math

import numpy as np

from ..core import memo as _memo
from ..core.block import Block
from ..core.errors import ParameterError
from ..core.params import finite_array, positive_scalar
from ..utility.arrays import batched, cache_rows, map_rows
from ._graph import NeighborSource


def sigma_norm(z, eps, xp=np):
    """``(sqrt(1 + eps |z|^2) - 1) / eps`` over the last axis."""
    return (xp.sqrt(1.0 + eps * xp.sum(z * z, axis=-1)) - 1.0) / eps


def bump(s, h, xp=np):
    """Olfati-Saber's bump ``rho_h(s)``."""
    mid = 0.5 * (1.0 + xp.cos(np.pi * (s - h) / (1.0 - h)))
    return xp.where(s < h, 1.0, xp.where(s <= 1.0, mid, 0.0)) * (s >= 0)


def phi_alpha(s, r_a, d_a, a, b, h, xp=np):
    """Pairwise action ``rho_h(s / r_a) phi(s - d_a)`` on sigma-distances ``s``."""
    c = abs(a - b) / xp.sqrt(4.0 * a * b)
    z = s - d_a + c
    phi = 0.5 * ((a + b) * z / xp.sqrt(1.0 + z * z) + (a - b))
    return bump(s / r_a, h, xp) * phi


def _self_padded(idx, xp):
    """``idx`` (N, K) with the padding (-1) replaced by the agent's own index.

    A function of ``idx`` alone: :func:`~avblocks.core.memo.shared` computes
    it once per neighbour array, i.e. once per step for a neighbour set held
    over the step (a periodic ``Neighbors`` block), not once per RK4 stage.
    """
    return xp.where(idx >= 0, idx, xp.arange(idx.shape[0])[:, None])




#: ``sqrt(2) (-1)^j / (2 j + 1)!``: ``sqrt(2) sin(w)`` is ``w`` times a
#: polynomial in ``w^2`` with these coefficients (the Taylor series of sin up
#: to ``w^21``; its remainder is below 2e-18 on [0, pi/2])
_SQRT2_SIN = tuple(math.sqrt(2.0) * (-1) ** j / math.factorial(2 * j + 1)
                   for j in range(11))


def _two_sin_sq(w, xp):
    """``2 sin(w)^2 = 1 - cos(2 w)`` for ``w`` in [0, pi/2] (exactly 0 at
    ``w = 0``, 2 at ``pi/2`` to 1e-15).

    Under NumPy the library cosine (a vectorised ufunc: the fastest there).
    Under any other ``xp`` the polynomial of :data:`_SQRT2_SIN` (within 2e-15
    of the library functions): plain multiply-adds that fuse into XLA's
    loops, where a float64 cosine is a scalar library call (measured: a
    flocking stage about 1.3x faster under XLA at 10^3 agents)."""
    if xp is np:
        return 1.0 - np.cos(2.0 * w)
    w2 = w * w
    acc = _SQRT2_SIN[-1]
    for coef in _SQRT2_SIN[-2::-1]:
        acc = acc * w2 + coef
    s = w * acc
    return s * s


#: agents per block of the NumPy evaluation: the pair temporaries of one
#: block stay in the CPU's cache (measured 17 % faster than all pairs at
#: once at N = 10^4, 30 % at 10^5)
NUMPY_BLOCK = 1024


def flocking_law(position, velocity, idx, d, r, *, eps=0.1, a=5.0, b=5.0, h=0.2,
                 c1=1.0, c2=1.0, xp=np):
    r"""Olfati-Saber's u^alpha (N, D) for neighbour lists ``idx`` (N, K).

    The equations of the module docstring, rearranged so that every
    intermediate is one (N, K) array and the scalar constants are folded
    before they meet an array:

    * padded slots point at the agent itself (``dq = 0``: they add nothing
      to the position term and cancel, to rounding, in the velocity term); the
      padded index is computed once per neighbour array (:func:`_self_padded`);
    * one square root per pair: ``R = sqrt(1 / eps^2 + |dq|^2 / eps) =
      sqrt(1 + eps |dq|^2) / eps``, so ``||dq||_s = R - 1 / eps``,
      ``sigma_eps(dq) = dq / (eps R)``, and ``s / r_a`` in ``[h, 1]`` is
      ``R`` in ``[lo, hi] = [1 / eps + h r_a, 1 / eps + r_a]``: the bump is
      ``rho = (1 + cos(pi (clip(R, lo, hi) - lo) / (hi - lo))) / 2 =
      sin(w)^2`` with ``w = pi (hi - clip(R, lo, hi)) / (2 (hi - lo))``
      (one clip instead of two nested selects; :func:`_two_sin_sq`: 1
      below ``h`` to 1e-15, exactly 0 beyond ``r``);
    * ``phi(s - d_a)`` takes ``z = R - (1 / eps + d_a - c)``;
    * ``u_i = c1 sum_j rho phi / root dq + c2 (sum_j rho p_j - p_i sum_j
      rho)``, with the 1/2 of the bump and the ``eps`` folded into scalars.

    Under NumPy the same expressions run over the listed pairs only, as
    flat arrays (:func:`_flat_pairs`, :func:`_alpha_pairs`: no work for
    padded slots, a pair listed both ways evaluated once for both agents,
    sums by ``np.bincount``), :data:`NUMPY_BLOCK` agents at a time (cache
    blocking); under other ``xp`` the (N, K) form above, all agents at
    once (static shapes), or, traced on a CPU for a fleet whose (N, K)
    tables outgrow the cache, in blocks of rows
    (:func:`~avblocks.utility.arrays.cache_rows`: N = 10^5 four
    evaluations 95 -> 54-64 ms). Same values as the equations written pair by pair to rounding
    (tested at 1e-12 against such a loop); traceable and smooth in the
    positions, velocities and gains (``clip`` has zero slope where the bump
    is flat).
    """
    rt = xp.sqrt
    ie = 1.0 / eps
    r_a = (rt(1.0 + eps * r * r) - 1.0) * ie
    d_a = (rt(1.0 + eps * d * d) - 1.0) * ie
    c = abs(a - b) / rt(4.0 * a * b)
    k = dict(ie=ie, c0=ie * ie, lo=ie + h * r_a, hi=ie + r_a,
             gain=0.5 * np.pi / ((1.0 - h) * r_a), shift=ie + d_a - c,
             ae=0.25 * (a + b) * ie, be=0.25 * (a - b) * ie, c1=c1, c2=0.5 * c2)
    if xp is np:
        return _alpha_pairs(position, velocity, _memo.shared(_flat_pairs, idx, np), k)
    nb = _memo.shared(_self_padded, idx, xp)                        # (N, K)
    qt, pt = position.T, velocity.T
    rows = cache_rows(nb.shape[0], nb.shape[1], position.dtype, xp,
                      batched([position, velocity, nb]))
    if rows is None:
        return _alpha_block(qt, pt, nb, slice(None), k, xp)
    # a large fleet on a CPU: blocks of rows, each pass of the law in cache
    (acc,) = map_rows(lambda b, own: (_alpha_block(qt, pt, b, own, k, xp),),
                      [nb, xp.arange(nb.shape[0])], xp, rows)
    return acc


def _flat_pairs(idx, xp=np):
    """The listed pairs of ``idx`` (N, K) as flat arrays for
    :func:`_alpha_pairs` (NumPy), in blocks of :data:`NUMPY_BLOCK` agents.

    A pair listed both ways (``j`` in row ``i`` and ``i`` in row ``j``: most
    pairs) is kept once, as ``i < j``, and evaluated once for both agents
    (its sigma-distance, bump and action are symmetric); the others once
    each. Found by sorting packed integer keys (a value sort, no argsort):
    ``(min(i, j), max(i, j), i > j)`` in bit fields, so the two listings of a
    pair are neighbours. Each block is ``(a, top, il, i, j, jl, m)``: the
    pairs whose ``i`` is one of the agents ``a:a + NUMPY_BLOCK``, the ``m``
    mirrored ones first (``j`` may lie beyond the block: ``top`` is one
    past the largest agent touched); ``il = i - a``, ``jl = j - a`` of the
    mirrored ones. A function of ``idx`` alone
    (:func:`~avblocks.core.memo.shared`: once per neighbour array, not once
    per RK4 stage)."""
    idx = np.asarray(idx)
    n = idx.shape[0]
    ok = idx >= 0
    jj = idx[ok].astype(np.int64)
    ii = np.repeat(np.arange(n, dtype=np.int64), np.count_nonzero(ok, axis=1))
    bits = max(1, (n - 1).bit_length())
    mask = (1 << bits) - 1
    lo, hi = np.minimum(ii, jj), np.maximum(ii, jj)
    key = lo << bits
    key |= hi
    key <<= 1
    key |= ii > jj
    key.sort()
    dup = key[1:] == key[:-1]
    twin = ((key[1:] ^ key[:-1]) == 1) & ~(key[:-1] & 1).astype(bool)
    if dup.any():                      # a pair listed twice in one row:
        twin[:] = False                # no mirroring (plain, exact sums)
    first = np.zeros(key.size, bool)
    first[:-1] = twin
    paired = first.copy()
    paired[1:] |= twin
    u = key[first] >> 1
    mi, mj = u >> bits, u & mask       # mirrored: i < j, sorted by i
    s = key[~paired]
    us, flip = s >> 1, (s & 1).astype(bool)
    slo, shi = us >> bits, us & mask
    sk = np.where(flip, (shi << bits) | slo, us)
    sk.sort()
    si, sj = sk >> bits, sk & mask     # singles sorted by i
    out = []
    for a in range(0, n, NUMPY_BLOCK):
        b = min(a + NUMPY_BLOCK, n)
        m0, m1 = np.searchsorted(mi, (a, b))
        s0, s1 = np.searchsorted(si, (a, b))
        i = np.concatenate([mi[m0:m1], si[s0:s1]])
        j = np.concatenate([mj[m0:m1], sj[s0:s1]])
        top = max(b, int(mj[m0:m1].max()) + 1) if m1 > m0 else b
        out.append((a, top, i - a, i, j, mj[m0:m1] - a, int(m1 - m0)))
    return out


def _alpha_pairs(position, velocity, pairs, k):
    """u^alpha under NumPy over the listed pairs only (``pairs`` from
    :func:`_flat_pairs`): the expressions of :func:`_alpha_block` on flat
    (P,) arrays, each pair listed both ways evaluated once for both agents,
    the neighbour sums by ``np.bincount`` -- no work for the padded slots
    (about a third of them on the flocking benchmarks). ``c1`` is folded
    into ``f``, ``c2 / 2`` into the velocities; temporaries are reused
    (``out=``), never the inputs."""
    n, dim = position.shape
    qt = position.T.copy()                                         # (D, N)
    pt = np.multiply(velocity.T, k["c2"], order="C")               # c2 / 2 p (rows
    #                          contiguous: take() of a strided row copies all of it)
    ae, be = k["c1"] * k["ae"], k["c1"] * k["be"]
    shift, lo, hi, gain2 = k["shift"], k["lo"], k["hi"], 2.0 * k["gain"]
    acc = np.zeros((dim, n))
    gsum = np.zeros(n)
    for a, top, il, i, j, jl, mm in pairs:
        if j.size == 0:
            continue
        m = top - a
        dq = []
        for c in range(dim):
            x = qt[c].take(j)
            x -= qt[c].take(i)
            dq.append(x)
        t = dq[0] * dq[0]
        for c in range(1, dim):
            t += dq[c] * dq[c]
        t *= k["ie"]
        t += k["c0"]
        big_r = np.sqrt(t, out=t)                  # sqrt(1 + eps |dq|^2) / eps
        z = big_r - shift
        f = z * z
        f += 1.0
        np.sqrt(f, out=f)
        np.divide(z, f, out=f)
        f *= ae
        if be:
            f += be
        f /= big_r                                 # c1 phi / (2 root), folded
        g = big_r.clip(lo, hi, out=z)
        np.subtract(hi, g, out=g)
        g *= gain2
        np.cos(g, out=g)
        np.subtract(1.0, g, out=g)                 # 2 rho (exactly 0 beyond r)
        gm = g[:mm]
        gsum[a:top] += np.bincount(il, g, minlength=m)
        if mm:
            gsum[a:top] += np.bincount(jl, gm, minlength=m)
        for c in range(dim):
            fd = np.multiply(f, dq[c], out=dq[c])  # c1 phi sigma_eps(q_j - q_i) / 2
            if mm:                                 # the mirror: j's term, q_i - q_j
                wj = pt[c].take(i[:mm])
                wj -= fd[:mm]
                wj *= gm
            fd += pt[c].take(j)
            fd *= g
            acc[c, a:top] += np.bincount(il, fd, minlength=m)
            if mm:
                acc[c, a:top] += np.bincount(jl, wj, minlength=m)
    acc -= pt * gsum
    return np.ascontiguousarray(acc.T)


#: largest gathered neighbour table (bytes, float64) that
#: :func:`_alpha_block` takes as one gather of rows rather than one gather
#: per column: measured (XLA CPU, CPU time per step) 9 % faster for the
#: 50-agent flocking ensemble (19 kB per run), the same at 10^3 agents
#: (384 kB), 10 % slower at 10^4 (3.8 MB: the strided columns of the rows
#: leave the cache)
ROW_GATHER_BYTES = 512 * 1024


def _alpha_block(qt, pt, nb, own, k, xp):
    """u^alpha of the agents ``own`` (their neighbours ``nb``, (m, K)) from
    all positions and velocities ``qt``, ``pt`` (D, N); (m, D)."""
    dim = qt.shape[0]
    if nb.size * 2 * dim * 8 <= ROW_GATHER_BYTES:
        # one gather of the neighbours' rows (position and velocity, 2 D
        # values each): the same numbers as 2 D gathers of single values
        rows = xp.concatenate([qt, pt], axis=0).T[nb]               # (m, K, 2 D)
        cols = [rows[..., c] for c in range(2 * dim)]
    else:
        cols = [qt[c][nb] for c in range(dim)] + [pt[c][nb] for c in range(dim)]
    dq = [cols[m] - qt[m, own][:, None] for m in range(dim)]        # (m, K)
    nrm2 = dq[0] * dq[0]
    for m in range(1, dim):
        nrm2 = nrm2 + dq[m] * dq[m]
    big_r = xp.sqrt(k["c0"] + nrm2 * k["ie"])                      # sqrt(1 + eps |dq|^2) / eps
    z = big_r - k["shift"]
    f = (k["ae"] * z / xp.sqrt(1.0 + z * z) + k["be"]) / big_r     # phi / (2 root)
    g = _two_sin_sq((k["hi"] - xp.clip(big_r, k["lo"], k["hi"])) * k["gain"], xp)  # 2 rho
    # g only meets the neighbour sums: XLA then evaluates the bump once per
    # stage (an elementwise consumer of g, such as g * f, made it recompute
    # the bump in a second fused loop)
    gsum = xp.sum(g, axis=1)
    out = [k["c1"] * xp.sum(g * (f * dq[m]), axis=1)
           + k["c2"] * (xp.sum(g * cols[dim + m], axis=1) - pt[m, own] * gsum)
           for m in range(dim)]
    return xp.stack(out, axis=1)


def order_parameter(velocity, xp=np):
    """Velocity alignment ``|sum_i p_i| / sum_i |p_i|`` in [0, 1] (1: aligned)."""
    return xp.sqrt(xp.sum(xp.sum(velocity, axis=0) ** 2)) / xp.maximum(
        xp.sum(xp.sqrt(xp.sum(velocity * velocity, axis=-1))), 1e-300)


class Flocking(Block):
    """Olfati-Saber flocking (alpha-lattice) for N double integrators.

    Ports
    -----
    position, velocity : in, (N, D).
    neighbors : in, (N, K) int64 (port mode only; e.g. agents within ``r``).
    accel : out, (N, D) — acceleration command ``u^alpha (+ u^gamma)``.

    Parameters
    ----------
    n : int;  dim : int (default 2);  d : float > 0 — lattice distance (m).
    r : float > d — interaction range (default 1.2 d).
    eps, a, b, h, c1, c2 : law constants (module docstring).
    gamma : bool — add the navigational term towards ``target``.
    target : (D,) or (N, D); target_velocity : same; c1_gamma, c2_gamma.
    radius mode: ``neighbors="internal"`` with ``k_max`` computes neighbours
    within ``r`` inside the block (compiles: ``utility.spatial``); ``adjacency``
    a fixed graph.

    Notes
    -----
    ``d``, ``r``, ``eps``, ``a``, ``b``, ``h``, ``c1``, ``c2``, ``target``,
    ``target_velocity`` (both (N, D)), ``c1_gamma`` and ``c2_gamma`` are
    numeric parameters (``"flock.c1"``...; the constraints ``r > d`` and
    ``a <= b`` are checked at construction only); ``gamma``, ``neighbors``,
    ``k_max``, ``adjacency``, ``n`` and ``dim`` are structural.

    Compiles (``backend="jax"``) and differentiates: the law is written in
    ``xp`` (:func:`flocking_law`); traced, the bump's cosine is a polynomial
    within 2e-15 of the NumPy engine's library cosine.

    Reference: R. Olfati-Saber, IEEE TAC 51(3):401-420, 2006, Algorithm 1
    (and the gamma term of Algorithm 2).
    """

    #: Arguments of a small instance (the editor's palette template).
    example = {"n": "$agents", "d": 7.0}

    def __init__(self, n, d, *, r=None, dim=2, eps=0.1, a=5.0, b=5.0, h=0.2,
                 c1=1.0, c2=1.0, gamma=False, target=0.0, target_velocity=0.0,
                 c1_gamma=0.2, c2_gamma=0.4, neighbors="port", k_max=None,
                 adjacency=None):
        super().__init__()
        name = "Flocking"
        self.n = n = int(n)
        dim = int(dim)
        d = positive_scalar(d, name, "d")
        r = 1.2 * d if r is None else positive_scalar(r, name, "r")
        if r <= d:
            raise ParameterError("interaction range r must exceed d", block=name,
                                 param="r", expected=f"> {d}", found=r)
        a, b = positive_scalar(a, name, "a"), positive_scalar(b, name, "b")
        if a > b:
            raise ParameterError("need 0 < a <= b", block=name, param="a",
                                 expected=f"<= b = {b}", found=a)
        if not 0 < float(h) < 1:
            raise ParameterError("h must lie in (0, 1)", block=name, param="h", found=h)
        dp = self.declare_parameter
        dp("d", d, bounds=(1e-12, None), unit="m", doc="lattice distance")
        dp("r", r, bounds=(1e-12, None), unit="m", doc="interaction range (> d)")
        dp("eps", positive_scalar(eps, name, "eps"), bounds=(1e-12, None))
        dp("a", a, bounds=(1e-12, None))
        dp("b", b, bounds=(1e-12, None))
        dp("h", float(h), bounds=(1e-9, 1 - 1e-9))
        dp("c1", positive_scalar(c1, name, "c1", allow_zero=True), bounds=(0, None))
        dp("c2", positive_scalar(c2, name, "c2", allow_zero=True), bounds=(0, None))
        self.gamma = bool(gamma)
        dp("target", np.broadcast_to(finite_array(target, name, "target"), (n, dim)),
           unit="m")
        dp("target_velocity", np.broadcast_to(
            finite_array(target_velocity, name, "target_velocity"), (n, dim)), unit="m/s")
        dp("c1_gamma", positive_scalar(c1_gamma, name, "c1_gamma", allow_zero=True),
           bounds=(0, None))
        dp("c2_gamma", positive_scalar(c2_gamma, name, "c2_gamma", allow_zero=True),
           bounds=(0, None))
        self.declare_input("position", (n, dim), unit="m")
        self.declare_input("velocity", (n, dim), unit="m/s")
        if neighbors not in ("port", "internal"):
            raise ParameterError("neighbors must be 'port' or 'internal'", block=name,
                                 param="neighbors", found=neighbors)
        radius = r if neighbors == "internal" else None
        self.graph = NeighborSource(self, n, adjacency=adjacency, radius=radius,
                                    k_max=k_max, radius_param="r")
        self.declare_output("accel", (n, dim), unit="m/s^2")

    def configure(self, inputs):
        self.graph.configure(inputs)

    def output(self, t, x, u, xp):
        q, p = u["position"], u["velocity"]
        idx = self.graph.indices(u, q, xp)
        acc = flocking_law(q, p, idx, self.d, self.r, eps=self.eps, a=self.a,
                           b=self.b, h=self.h, c1=self.c1, c2=self.c2, xp=xp)
        if self.gamma:
            q_r = self.target + self.target_velocity * t
            acc = acc - self.c1_gamma * (q - q_r) - self.c2_gamma * (
                p - self.target_velocity)
        return {"accel": acc}
