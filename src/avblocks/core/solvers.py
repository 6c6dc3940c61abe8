"""Integrators. They live only here, never inside blocks.

A solver advances the continuous states of a whole diagram over one major
step ``h``. Fixed-step solvers (:class:`Euler`, :class:`RK4`) call the
engine's pure functions, so they also run traced under JAX. :class:`Scipy`
hands the flattened state to :func:`scipy.integrate.solve_ivp`.

The engine interface a solver uses:

``eng.derivs(t, X, Y) -> K``
    derivatives of every continuous state, given states ``X`` and the outputs
    ``Y`` that belong to them;
``eng.minor_outputs(t, X, Y) -> Y``
    outputs at a solver stage (discrete blocks hold their values);
``eng.axpy(X, a, K) -> X + a*K`` and ``eng.combine(X, [(a_i, K_i)])``.
"""

from __future__ import annotations

import numpy as np

from .errors import ParameterError


class Solver:
    """Base class; subclasses implement :meth:`step`."""

    name = "solver"
    order = None
    fixed_step = True

    def step(self, eng, t, X, Y, h):  # pragma: no cover - abstract
        raise NotImplementedError

    def __repr__(self):
        return f"{type(self).__name__}()"


class Euler(Solver):
    """Forward Euler: ``x+ = x + h f(t, x)``. First order."""

    name = "euler"
    order = 1

    def step(self, eng, t, X, Y, h):
        return eng.axpy(X, h, eng.derivs(t, X, Y))


class RK4(Solver):
    """Classical fourth-order Runge-Kutta. The default.

    Outputs of continuous blocks are recomputed at each of the four stages;
    discrete blocks hold theirs.
    """

    name = "rk4"
    order = 4

    def step(self, eng, t, X, Y, h):
        k1 = eng.derivs(t, X, Y)
        X2 = eng.axpy(X, 0.5 * h, k1)
        k2 = eng.derivs(t + 0.5 * h, X2, eng.minor_outputs(t + 0.5 * h, X2, Y))
        X3 = eng.axpy(X, 0.5 * h, k2)
        k3 = eng.derivs(t + 0.5 * h, X3, eng.minor_outputs(t + 0.5 * h, X3, Y))
        X4 = eng.axpy(X, h, k3)
        k4 = eng.derivs(t + h, X4, eng.minor_outputs(t + h, X4, Y))
        return eng.combine(X, [(h / 6, k1), (h / 3, k2), (h / 3, k3), (h / 6, k4)])


class Scipy(Solver):
    """Variable-step integration with :func:`scipy.integrate.solve_ivp`.

    Integrates adaptively with the given method (``RK45``, ``DOP853``,
    ``LSODA``, ``Radau``, ``BDF``...) and tolerances, restarting where
    discrete states may change: at every major step when a continuous block
    has discrete (mode) states, otherwise only at the sample hits of
    periodic blocks, with the major-step grid as output times in between.
    """

    fixed_step = False
    _methods = ("RK45", "RK23", "DOP853", "LSODA", "Radau", "BDF")

    def __init__(self, method="RK45", *, rtol=1e-6, atol=1e-9, max_step=np.inf):
        if method not in self._methods:
            raise ParameterError("unknown solve_ivp method", param="method",
                                 expected=f"one of {self._methods}", found=method)
        self.method = method
        self.rtol = float(rtol)
        self.atol = float(atol)
        self.max_step = float(max_step)
        self.name = method.lower()
        self.nfev = 0

    def __repr__(self):
        return f"Scipy({self.method!r}, rtol={self.rtol}, atol={self.atol})"

    def _solve(self, eng, t, X, Y, t_end, max_step, t_eval=None):
        """One ``solve_ivp`` of the packed continuous states from ``t``;
        discrete blocks hold their outputs ``Y`` throughout."""
        from scipy.integrate import solve_ivp

        def f(tt, yy):
            Xs = eng.unpack(yy, X)
            return eng.pack_derivs(eng.derivs(tt, Xs, eng.minor_outputs(tt, Xs, Y)))

        sol = solve_ivp(f, (t, t_end), eng.pack(X), method=self.method, rtol=self.rtol,
                        atol=self.atol, max_step=max_step, t_eval=t_eval)
        self.nfev += sol.nfev
        if not sol.success:
            from .errors import SimulationError
            raise SimulationError(f"solve_ivp ({self.method}) failed: {sol.message}",
                                  time=t)
        return sol

    def step(self, eng, t, X, Y, h):
        if eng.size == 0:
            return X
        sol = self._solve(eng, t, X, Y, t + h, min(self.max_step, h))
        return eng.unpack(sol.y[:, -1], X)

    def integrate(self, eng, t, X, Y, t_evals):
        """States at each of ``t_evals`` (increasing, after ``t``) in one
        adaptive solve: used between discrete events, where nothing else can
        change the derivatives."""
        if eng.size == 0:
            return [X for _ in t_evals]
        sol = self._solve(eng, t, X, Y, t_evals[-1], self.max_step, t_eval=t_evals)
        return [eng.unpack(sol.y[:, j], X) for j in range(sol.y.shape[1])]


_BY_NAME = {"euler": Euler, "rk4": RK4}


def make_solver(spec) -> Solver:
    """A solver from a name (``"rk4"``, ``"euler"``, ``"RK45"``, ``"DOP853"``,
    ``"LSODA"``...) or a :class:`Solver` instance."""
    if isinstance(spec, Solver):
        return spec
    if isinstance(spec, str):
        if spec.lower() in _BY_NAME:
            return _BY_NAME[spec.lower()]()
        for m in Scipy._methods:            # "radau", "bdf", "rk45": any case
            if spec.upper() == m.upper():
                return Scipy(m)
    raise ParameterError("unknown solver", param="solver",
                         expected="'rk4', 'euler', a solve_ivp method name "
                                  f"{Scipy._methods} or a Solver object",
                         found=repr(spec))
