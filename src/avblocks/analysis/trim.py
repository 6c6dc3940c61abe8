r"""Equilibria of a diagram (trim): states and inputs where nothing moves.

:func:`trim` solves

.. math::

    f(t, x, u) = 0 \ \text{(continuous)}\quad\text{or}\quad
    \Phi(x, u) - x = 0 \ \text{(sampled)},\qquad
    g(t, x, u) = y^\star \ \text{(where given)}

for the free entries of the states ``x`` and of the input perturbations
``u`` with :func:`scipy.optimize.least_squares` (trust-region reflective,
which also handles more unknowns than equations: an equilibrium of a
consensus network or of a formation is a whole family) on the exact
Jacobians of :class:`~avblocks.analysis.Linearizer` (the compiled engine's
functions differentiated by JAX). Entries given as numbers in ``fixed``
or ``outputs`` are held; ``NaN`` entries are free. The result reports the
residual; when it stays above ``tol`` there is no equilibrium near the
starting point with those constraints and :class:`TrimError` says so (the
best point found is ``err.result``).

Reference: The MathWorks, Simulink ``trim`` and ``findop`` (operating
points from specifications of states, inputs and outputs); J. Nocedal and
S. J. Wright, *Numerical Optimization* (2nd ed., 2006), ch. 10 (nonlinear
least squares).
"""

from __future__ import annotations

import numpy as np

from ..core.diagram import PortRef
from ..core.errors import AvError, ParameterError
from .linearize import Linearizer, _path_of, _time
from .model import TrimResult


class TrimError(AvError):
    """No equilibrium was found; ``result`` is the best point reached."""

    def __init__(self, cause, *, result=None, **kw):
        self.result = result
        super().__init__(cause, **kw)


def _masked(lin, spec, names, what):
    """``(indices, values)`` of the numbers (non-NaN entries) of a dict
    ``{path: array}`` over the vector laid out by ``names`` (a dict path ->
    slice)."""
    idx, vals = [], []
    if spec is None:
        return np.zeros(0, int), np.zeros(0)
    if not isinstance(spec, dict):
        raise ParameterError(f"{what} must be a dict {{'block.name': array}}", param=what,
                             found=type(spec).__name__)
    for k, v in spec.items():
        k = _path_of(k)
        if k not in names:
            raise ParameterError(f"{what} names an unknown entry", param=k,
                                 expected=sorted(names), found=k)
        sl, shape = names[k]
        a = np.asarray(v, dtype=float)
        if a.ndim == 0:
            a = np.full(shape, float(a))
        if a.shape != shape:
            raise ParameterError(f"{what} value has the wrong shape", param=k,
                                 expected=shape, found=a.shape)
        if np.any(np.isinf(a)):
            raise ParameterError(f"{what} values must be finite numbers or NaN (free)",
                                 param=k)
        flat = a.ravel()
        keep = ~np.isnan(flat)
        idx.append(np.arange(sl.start, sl.stop)[keep])
        vals.append(flat[keep])
    if not idx:
        return np.zeros(0, int), np.zeros(0)
    return np.concatenate(idx), np.concatenate(vals)


def trim(diagram, at=None, *, fixed=None, outputs=None, inputs=(), steady=None,
         params=None, t=0.0, kind="auto", dt=None, tol=1e-8, max_evaluations=200,
         seed=0) -> TrimResult:
    r"""Find an equilibrium of ``diagram`` (module docstring).

    Parameters
    ----------
    diagram : Diagram
    at : dict or TrimResult, optional
        Starting point, as for :func:`~avblocks.analysis.linearize`
        (``{"block.state": value}``; default: the initial states).
    fixed : dict, optional
        ``{"block.state": array}``: entries held at these values (``NaN``
        entries stay free).
    outputs : dict, optional
        ``{"block.port": array}``: required output values (``NaN``: free).
    inputs : list of str
        Input ports whose perturbations are free unknowns (e.g. the thrust
        that holds a hover), starting from 0 or their value in ``at``.
    steady : list of str, optional
        The states whose derivative must vanish (default: every state of
        the model); leave out one that drifts on purpose.
    params, t, kind, dt, seed
        As :func:`~avblocks.analysis.linearize`.
    tol : float
        Largest residual accepted.
    max_evaluations : int
        Budget of function evaluations of the least-squares solver.

    Returns
    -------
    TrimResult
        Usable as ``at=`` of :func:`~avblocks.analysis.linearize`.

    Raises
    ------
    TrimError
        The residual stayed above ``tol`` (no equilibrium with these
        constraints near the start); ``err.result`` is the best point.

    Examples
    --------
    >>> import numpy as np, avblocks as av
    >>> d = av.Diagram()
    >>> src = d.add(av.blocks.Constant([[1.0]]), name="src")
    >>> g = d.add(av.blocks.Gain(-2.0), name="g")
    >>> x = d.add(av.blocks.Integrator([[0.0]]), name="x")
    >>> s = d.add(av.blocks.Sum("++"), name="s")
    >>> _ = d.connect(x.y, g.u), d.connect(g.y, s.u0), d.connect(src.y, s.u1)
    >>> _ = d.connect(s.y, x.u)
    >>> tr = av.trim(d)                 # dx/dt = -2 x + 1 = 0
    >>> float(tr.states["x.x"][0, 0]), tr.residual < 1e-12
    (0.5, True)
    """
    from scipy.optimize import least_squares
    if isinstance(inputs, (str, PortRef)):
        inputs = [inputs]
    out_names = [] if outputs is None else list(outputs) if isinstance(outputs, dict) \
        else None
    if out_names is None:
        raise ParameterError("outputs must be a dict {'block.port': array}",
                             param="outputs", found=type(outputs).__name__)
    try:
        tol = float(tol)
        max_evaluations = int(max_evaluations)
    except (TypeError, ValueError):
        raise ParameterError("tol is a number, max_evaluations an integer",
                             param="tol") from None
    if not tol > 0 or max_evaluations < 1:
        raise ParameterError("tol must be > 0 and max_evaluations >= 1", param="tol",
                             found=(tol, max_evaluations))
    lin = Linearizer(diagram, inputs=inputs, outputs=out_names, kind=kind, dt=dt,
                     seed=seed)
    t = _time(t)
    X, u0 = lin.base_states(at)
    theta = lin._theta(params)
    x0 = lin.pack(X)
    n = lin.nx
    st = {k: (sl, tuple(lin.cd.blocks[lin.cd.index(k.rpartition(".")[0])]
                        ._init[k.rpartition(".")[2]].shape))
          for k, sl in lin.state_slots.items()}
    fix_idx, fix_val = _masked(lin, fixed, st, "fixed")
    oslices, off = {}, 0
    for path, _i, _o, spec in lin.outs:
        size = int(np.prod(spec.shape, dtype=np.int64))
        oslices[path] = (slice(off, off + size), tuple(spec.shape))
        off += size
    out_idx, out_val = _masked(lin, outputs, oslices, "outputs")
    if steady is None:
        rows = np.arange(n)
    else:
        steady = [steady] if isinstance(steady, str) else list(steady)
        bad = [s for s in steady if s not in lin.state_slots]
        if bad:
            raise ParameterError("steady names unknown states", param="steady",
                                 expected=sorted(lin.state_slots), found=bad)
        rows = np.concatenate([np.arange(lin.state_slots[s].start, lin.state_slots[s].stop)
                               for s in steady]) if steady else np.zeros(0, int)
    x_start = x0.copy()
    x_start[fix_idx] = fix_val
    free_x = np.setdiff1d(np.arange(n), fix_idx)
    z0 = np.concatenate([x_start[free_x], u0])
    sampled = lin.kind == "sampled"

    def split(z):
        x = x_start.copy()
        x[free_x] = z[:len(free_x)]
        return x, z[len(free_x):]

    def residual(z, jacobian=False):
        x, u = split(z)
        res = lin.evaluate(x, u, X, theta, t, jacobian=jacobian)
        f, y = res[0], res[1]
        r = np.concatenate([(f - x)[rows] if sampled else f[rows], y[out_idx] - out_val])
        if not jacobian:
            return r
        (A, B), (C, D) = res[2], res[3]
        if sampled:
            A = A - np.eye(n)
        J = np.vstack([np.hstack([A[np.ix_(rows, free_x)], B[rows]]),
                       np.hstack([C[np.ix_(out_idx, free_x)], D[out_idx]])])
        return r, J

    cache = {}

    def fun(z):
        r, J = residual(z, True)
        cache["J"] = (z.copy(), J)
        return r

    def jac(z):
        zz, J = cache.get("J", (None, None))
        if zz is None or not np.array_equal(zz, z):
            return residual(z, True)[1]
        return J

    if len(z0) == 0:
        r = residual(z0)
        nfev, msg = 1, "nothing free: the residual at the given point"
        z = z0
    else:
        sol = least_squares(fun, z0, jac=jac, method="trf", xtol=1e-15, ftol=1e-15,
                            gtol=1e-15, max_nfev=max_evaluations)
        z, nfev, msg = sol.x, int(sol.nfev), str(sol.message)
        r = residual(z)
    x, u = split(z)
    ymap = lin.evaluate(x, u, X, theta, t, jacobian=False)[1]
    worst = float(np.max(np.abs(r))) if r.size else 0.0
    result = TrimResult(lin.unpack(x), lin.unpack_inputs(u),
                        {p: ymap[sl].reshape(sh) for p, (sl, sh) in oslices.items()},
                        worst, bool(worst <= tol), nfev, msg, x, u)
    if not np.isfinite(worst) or worst > tol:
        where = ""
        if r.size and np.isfinite(worst):
            k = int(np.argmax(np.abs(r)))
            names = ([("d/dt " if not sampled else "step of ") + lin.state_names[j]
                      for j in rows] + [lin.output_names[j] for j in out_idx])
            where = f"; largest at {names[k]}"
        raise TrimError(f"no equilibrium found: residual {worst:.3g} > tol {tol:g}{where}",
                        result=result, found=msg,
                        hint="free more states or inputs (NaN in fixed=/outputs=, "
                             "inputs=[...]), start nearer (at=...), or leave a drifting "
                             "state out of steady=")
    return result
