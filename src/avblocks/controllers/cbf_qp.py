"""The quadratic programs behind the CBF safety filter
(:mod:`avblocks.controllers.collision_avoidance`): the small exact
per-agent QP (closed form over active sets), the joint QP by Clarabel
(NumPy, the ``safety`` extra) and by ADMM written in ``xp`` (traceable,
differentiable, fixed budget)."""

from __future__ import annotations

import itertools

import numpy as np

from ..core.errors import ParameterError


def _subsets(k, dim):
    return [np.array(c, dtype=np.int64) for m in range(1, dim + 1)
            for c in itertools.combinations(range(k), m)]


def min_norm_qp(u_nom, a, b, mask, xp=np, tol=1e-9):
    """Exact ``argmin |u - u_nom|^2 s.t. a_k . u <= b_k`` (k where ``mask``).

    ``u_nom`` (N, D), ``a`` (N, K, D), ``b`` (N, K), ``mask`` (N, K) bool.
    Enumerates active sets of size <= D (see the module docstring). A set of
    ``D`` constraints is solved as the square system ``A_s u = b_s`` itself
    (the vertex), not through its Gram matrix, whose condition number is
    the square of it: nearly antiparallel constraints (the corner of a thin
    wedge) stay exact. Feasibility is tested to ``tol`` relative to the size
    of each constraint (``|a_k| |u| + |b_k|``).
    """
    n, k, dim = a.shape
    big = 1e300
    bm = xp.where(mask, b, big)
    a = xp.where(mask[..., None], a, 0.0)
    b0 = xp.where(mask, b, 0.0)
    cands, valid = [u_nom], [xp.ones(n, dtype=bool)]
    for s in _subsets(k, dim):
        a_s = a[:, s, :]                                   # (N, m, D)
        b_s = b0[:, s]
        m = len(s)
        if m == dim:
            # the vertex: A_s u = b_s (condition number of A_s, not A_s A_s^T)
            if dim == 2:
                det = a_s[:, 0, 0] * a_s[:, 1, 1] - a_s[:, 0, 1] * a_s[:, 1, 0]
                scale = (xp.sqrt(xp.sum(a_s[:, 0] ** 2, -1))
                         * xp.sqrt(xp.sum(a_s[:, 1] ** 2, -1)))
                det_ok = xp.abs(det) > 1e-13 * scale
                dd = xp.where(det_ok, det, 1.0)
                u = xp.stack([(a_s[:, 1, 1] * b_s[:, 0] - a_s[:, 0, 1] * b_s[:, 1]) / dd,
                              (a_s[:, 0, 0] * b_s[:, 1] - a_s[:, 1, 0] * b_s[:, 0]) / dd],
                             axis=-1)
            else:
                det = xp.linalg.det(a_s)
                scale = xp.prod(xp.sqrt(xp.sum(a_s ** 2, -1)), axis=-1)
                det_ok = xp.abs(det) > 1e-13 * scale
                as_ = xp.where(det_ok[:, None, None], a_s, xp.eye(m))
                u = xp.linalg.solve(as_, b_s[..., None])[..., 0]
            # a vertex is the optimum of its set only when the multipliers
            # are >= 0; the nearest-feasible choice below settles that
            good = xp.all(mask[:, s], axis=1) & det_ok
            cands.append(xp.where(good[:, None], u, u_nom))
            valid.append(good)
            continue
        r = xp.sum(a_s * u_nom[:, None, :], axis=-1) - b_s
        g = xp.einsum("nid,njd->nij", a_s, a_s)             # (N, m, m)
        if m == 1:
            det_ok = g[:, 0, 0] > 1e-300
            lam = (r[:, 0] / xp.where(det_ok, g[:, 0, 0], 1.0))[:, None]
        else:                                              # m = 2 < D = 3
            det = g[:, 0, 0] * g[:, 1, 1] - g[:, 0, 1] * g[:, 1, 0]
            det_ok = xp.abs(det) > 1e-13 * g[:, 0, 0] * g[:, 1, 1]
            dd = xp.where(det_ok, det, 1.0)
            lam = xp.stack([(g[:, 1, 1] * r[:, 0] - g[:, 0, 1] * r[:, 1]) / dd,
                            (g[:, 0, 0] * r[:, 1] - g[:, 1, 0] * r[:, 0]) / dd], axis=-1)
        good = xp.all(mask[:, s], axis=1) & det_ok
        cands.append(xp.where(good[:, None], u_nom - xp.sum(lam[..., None] * a_s, axis=1),
                              u_nom))
        valid.append(good)
    c = xp.stack(cands, axis=1)                            # (N, C, D)
    ok = xp.stack(valid, axis=1)                           # (N, C)
    viol = xp.einsum("nkd,ncd->nck", a, c) - bm[:, None, :]   # (N, C, K)
    anorm = xp.sqrt(xp.sum(a * a, axis=-1))                # (N, K)
    cnorm = xp.sqrt(xp.sum(c * c, axis=-1))                # (N, C)
    size = anorm[:, None, :] * cnorm[:, :, None] + xp.abs(b0)[:, None, :] + 1.0
    rel = viol / size
    worst = xp.max(xp.where(mask[:, None, :], rel, -big), axis=-1)
    worst = xp.where(ok, worst, big)
    dist = xp.sum((c - u_nom[:, None, :]) ** 2, axis=-1)
    dist = xp.where(ok & (worst <= tol), dist, xp.inf)
    best = xp.argmin(dist, axis=1)
    pick = xp.where(xp.isfinite(xp.min(dist, axis=1)), best, xp.argmin(worst, axis=1))
    return xp.take_along_axis(c, pick[:, None, None], axis=1)[:, 0, :]


def _clarabel():
    try:
        import clarabel
    except ImportError:
        raise ParameterError("mode='joint' needs the clarabel QP solver",
                             block="CollisionAvoidance", param="mode",
                             hint="pip install 'avblocks[safety]' (or: pip install "
                                  "clarabel), or use mode='agent'") from None
    return clarabel


def joint_min_norm_qp(u_nom, a, b):
    """``argmin sum |u - u_nom|^2 s.t. a @ u.ravel() <= b`` with Clarabel.

    ``u_nom`` (N, D); ``a`` a scipy.sparse (M, N*D) matrix; ``b`` (M,).
    Returns ``(u, status)``: (N, D) and Clarabel's status string.
    """
    import scipy.sparse as sp
    clarabel = _clarabel()
    shape = u_nom.shape
    q = -np.asarray(u_nom, dtype=float).ravel()
    nv = q.size
    if a.shape[0] == 0:
        return np.array(u_nom, dtype=float), "Solved"
    p_mat = sp.identity(nv, format="csc")
    a = sp.csc_matrix(a)
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.tol_gap_abs = settings.tol_gap_rel = 1e-10
    settings.tol_feas = 1e-10
    solver = clarabel.DefaultSolver(p_mat, q, a, np.asarray(b, dtype=float),
                                    [clarabel.NonnegativeConeT(a.shape[0])], settings)
    sol = solver.solve()
    return np.asarray(sol.x, dtype=float).reshape(shape), str(sol.status)


def scatter_add(n, index, values, xp=np):
    """``out[index[e]] += values[e]``: (n, ...) sums of (E, ...) rows."""
    if xp is np:
        index = np.asarray(index)
        values = np.asarray(values)
        if values.ndim == 1:
            return np.bincount(index, values, minlength=n)
        flat = values.reshape(len(values), -1)
        cols = [np.bincount(index, flat[:, c], minlength=n) for c in range(flat.shape[1])]
        return np.stack(cols, axis=1).reshape((n,) + values.shape[1:])
    return xp.zeros((n,) + tuple(values.shape[1:]), dtype=values.dtype).at[index].add(values)


def neighbor_edges(idx, xp=np):
    """Padded pair list ``(ei, ej, ok)`` (each (N*K,)) from neighbour lists (N, K).

    Edge ``(i, idx[i, k])`` is kept (``ok``) when the entry is real (``>= 0``,
    not ``i`` itself) and the pair is not listed twice: where ``j`` also
    lists ``i``, only the copy with ``i < j`` is kept, so the kept edges are
    the union of the lists, each pair once (as :func:`pairs_from_neighbors`).
    Static shapes: masked edges point from an agent to itself.
    """
    n, k = idx.shape
    own = xp.broadcast_to(xp.arange(n)[:, None], (n, k))
    real = (idx >= 0) & (idx != own)
    j = xp.where(real, idx, own)
    recip = xp.any(idx[j] == own[:, :, None], axis=-1)          # j lists i too
    ok = real & ((own < j) | ~recip)
    return own.reshape(-1), j.reshape(-1), ok.reshape(-1)


def _loop(n_chunks, body, state, xp):
    """``state = body(state)`` ``n_chunks`` times, skipping the calls once
    ``state[-1]`` (done) is true: a done state is a fixed point of ``body``,
    so the result is the same as calling it every time. NumPy: an early
    exit; JAX: ``lax.cond`` inside a ``fori_loop`` with a static trip count
    (reverse-mode differentiable; under ``vmap`` both branches run)."""
    if xp is np:
        for _ in range(n_chunks):
            if state[-1]:
                break
            state = body(state)
        return state
    import jax
    return jax.lax.fori_loop(
        0, n_chunks, lambda _, s: jax.lax.cond(s[-1], lambda s: s, body, s), state)


def admm_pair_qp(u_nom, ei, ej, ok, a, c, xp=np, *, iterations=500, tol=1e-10,
                 rho=1.0, alpha=1.6, check=10):
    r"""``argmin sum_i |u_i - w_i|^2 s.t. a_e^T (u_i - u_j) <= c_e`` (edges e = (i, j)).

    A fixed-iteration, traceable solver (pure ``xp``, static shapes) for
    the joint QP: consensus ADMM (Boyd et al. 2011, section 7; the
    over-relaxed form of section 3.4.3). Every edge keeps a copy
    ``z_e = (z_ei, z_ej)`` of its two agents' velocities, constrained to its
    half-space ``a_e^T (z_ei - z_ej) <= c_e``; the velocities are the
    consensus of the copies::

        u_i  = (2 w_i + rho sum_{e ∋ i} (z_e,i - y_e,i)) / (2 + rho deg_i)
        x_e  = alpha (u_i, u_j) + (1 - alpha) z_e
        z_e  = projection of x_e + y_e onto the half-space of e (closed form)
        y_e += x_e - z_e

    Each iteration costs O(N + E) (gathers and one scatter-add), no linear
    system. ``u_nom`` (N, D); ``ei, ej, ok`` (E,) padded edges (``ok``
    False: ignored); ``a`` (E, D); ``c`` (E,).

    Stopping: every ``check`` iterations the primal residual ``max |(u_i,
    u_j) - z_e|`` and the last change ``max |u^k - u^{k-1}|`` are compared
    with ``tol (1 + max |w|)``; once both are below it the iterate is frozen
    (a no-op under JAX, an early exit under NumPy: the same numbers). Under
    JAX the first ``check - 1`` iterations of each check are one
    ``fori_loop`` (one copy of the iteration in the compiled program: the
    swap tests compile about 9 % faster, same bits). At most ``iterations``
    (rounded up to a multiple of ``check``). Measured on random jammed
    20-agent clusters (about 100 pairs, many active): 100 iterations reach
    about 1e-6 of the exact solution, 200 about 1e-9; the defaults stop
    after 40 iterations on average in the swap case study, within 3e-10 of
    quadprog's exact active-set solution on the test clusters (``rho = 1``,
    ``alpha = 1.6``; the problem is invariant to the scale of ``a``, so
    ``rho`` needs no tuning per problem).

    Returns ``(u, residual)``: (N, D) and the last checked residual (a
    scalar; ``<= tol (1 + max|w|)`` when it converged).
    """
    n, dim = u_nom.shape
    if xp is np:
        # NumPy: drop the padding (it only adds exact zeros: same numbers)
        keep = np.flatnonzero(ok)
        ei, ej, ok, a, c = ei[keep], ej[keep], ok[keep], a[keep], c[keep]
    m = ei.shape[0]
    # both copies of every edge stacked: rows 0..m-1 for agent i, m..2m-1
    # for agent j; the half-space reads a2_e^T z_e,i + a2_e'^T z_e,j <= c_e
    idx2 = xp.concatenate([ei, ej])
    ok2 = xp.concatenate([ok, ok])
    okc = xp.where(ok2, 1.0, 0.0)[:, None]
    a2 = xp.concatenate([a, -a]) * okc                     # (2m, D)
    c = xp.where(ok, c, 0.0)
    an2 = 2.0 * xp.sum(a2[:m] * a2[:m], axis=-1)           # |(a, -a)|^2
    an2 = xp.where(an2 > 0, an2, 1.0)
    deg = scatter_add(n, idx2, okc[:, 0], xp)
    denom = (2.0 + rho * deg)[:, None]
    w2 = 2.0 * u_nom
    scale = tol * (1.0 + xp.max(xp.abs(u_nom)))
    if xp is np:
        flat = (idx2[:, None] * dim + np.arange(dim)).ravel()

        def gather_sum(v):                                  # scatter-add of (2m, D)
            return np.bincount(flat, v.ravel(), minlength=n * dim).reshape(n, dim)
    else:
        def gather_sum(v):
            return scatter_add(n, idx2, v, xp)

    def step(st):
        u, z, y = st
        un = (w2 + rho * gather_sum((z - y) * okc)) / denom
        v = alpha * un[idx2] + (1.0 - alpha) * z + y
        g = xp.sum(a2 * v, axis=-1)
        t = xp.maximum(g[:m] + g[m:] - c, 0.0) / an2
        z2 = v - xp.concatenate([t, t])[:, None] * a2
        return un, z2, v - z2

    def chunk(st):
        u, z, y, res, done = st
        inner = (u, z, y)
        if xp is np:
            for _ in range(check - 1):
                inner = step(inner)
        else:
            # one copy of the step in the program, not check - 1 unrolled
            import jax
            inner = jax.lax.fori_loop(0, check - 1, lambda _, s: step(s), inner)
        prev = inner[0]
        new = step(inner)
        un, z2 = new[0], new[1]
        rp = xp.max(xp.abs(un[idx2] - z2) * okc, initial=0.0)
        rd = xp.max(xp.abs(un - prev))
        r = xp.maximum(rp, rd)
        out = tuple(xp.where(done, o, nw) for o, nw in zip((u, z, y), new))
        return out + (xp.where(done, res, r), done | (r <= scale))

    z = u_nom[idx2]
    st = (u_nom, z, xp.zeros_like(z), xp.asarray(xp.inf), xp.asarray(False))
    n_chunks = max(1, -(-int(iterations) // int(check)))
    st = _loop(n_chunks, chunk, st, xp)
    return st[0], st[3]
