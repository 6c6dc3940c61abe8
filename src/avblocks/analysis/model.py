"""What the analysis returns: :class:`LinearModel` and :class:`TrimResult`."""

from __future__ import annotations

import difflib
from dataclasses import dataclass, field

import numpy as np

from ..core.errors import ParameterError


@dataclass
class LinearModel:
    r"""A linear state-space model of a diagram at an operating point.

    Continuous (``dt == 0``): ``dx/dt = f0 + A dx + B du``, ``y = y0 + C dx
    + D du``; sampled (``dt > 0``, the base period): ``x[k+1] = f0 + A dx +
    B du`` (``f0`` the state after one period from the operating point),
    ``y = y0 + C dx + D du``, where ``dx = x - x0`` and ``du = u - u0``.

    Attributes
    ----------
    A, B, C, D : ndarray
        ``(n, n)``, ``(n, m)``, ``(p, n)``, ``(p, m)``.
    dt : float
        0 for a continuous-time model, else the sample period [s].
    states, inputs, outputs : list of str
        Names of the entries (:mod:`avblocks.analysis.names`).
    x0, u0, y0, f0 : ndarray
        The operating point: states, input perturbations, outputs, and the
        state derivative (continuous) or next state (sampled) there.
    t : float
        Time of the operating point [s].
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    dt: float
    states: list
    inputs: list
    outputs: list
    x0: np.ndarray
    u0: np.ndarray
    y0: np.ndarray
    f0: np.ndarray
    t: float = 0.0
    state_slots: dict = field(default_factory=dict, repr=False)

    @property
    def continuous(self) -> bool:
        return self.dt == 0

    def poles(self) -> np.ndarray:
        """Eigenvalues of ``A``, sorted by real part then imaginary part (for
        a sampled model: points of the z-plane)."""
        ev = np.linalg.eigvals(self.A) if self.A.size else np.zeros(0, complex)
        return ev[np.lexsort((ev.imag, ev.real))]

    def _find(self, names, name, what):
        if name in names:
            return names.index(name)
        close = difflib.get_close_matches(str(name), names, n=3)
        raise ParameterError(f"no such {what} in this model", found=name,
                             hint=f"did you mean {close}?" if close else
                             f"its {what}s: {names[:8]}...")

    def state_index(self, name) -> int:
        """Position of the state entry ``name`` (``"fleet.pose[1].theta"``)."""
        return self._find(self.states, name, "state")

    def input_index(self, name) -> int:
        """Position of the input entry ``name`` (``"form.ref[1].l_ref"``)."""
        return self._find(self.inputs, name, "input")

    def output_index(self, name) -> int:
        """Position of the output entry ``name`` (``"form.error[1].l"``)."""
        return self._find(self.outputs, name, "output")

    def state(self, path) -> slice:
        """The rows of ``A`` of the state ``"block.state"`` (all its entries)."""
        if path not in self.state_slots:
            raise ParameterError("no such state in this model", found=path,
                                 expected=sorted(self.state_slots))
        return self.state_slots[path]

    def to_control(self, name=None):
        """This model as a :class:`control.StateSpace` (python-control, the
        ``analysis`` extra) with its state, input and output names; see
        :func:`avblocks.analysis.to_control`."""
        from .control import to_control
        return to_control(self, name=name)

    def __repr__(self):
        kind = "continuous" if self.continuous else f"sampled every {self.dt:g} s"
        return (f"LinearModel({kind}, {len(self.states)} states, {len(self.inputs)} "
                f"inputs, {len(self.outputs)} outputs, t={self.t:g})")


@dataclass
class TrimResult:
    """An equilibrium found by :func:`trim`.

    Attributes
    ----------
    states : dict
        ``{"block.state": array}`` of every state of the model (continuous,
        and floating-point discrete ones for a sampled model).
    inputs : dict
        ``{"block.port": array}``: the input perturbations at the point.
    outputs : dict
        ``{"block.port": array}`` of the outputs named in the call.
    residual : float
        Largest absolute residual: ``|dx/dt|`` (continuous) or
        ``|x[k+1] - x[k]|`` (sampled) of the steady states, and ``|y - y*|``
        of the fixed outputs.
    success : bool
        ``residual <= tol``.
    nfev : int
        Evaluations of the diagram's functions.
    message : str
        SciPy's message.
    """

    states: dict
    inputs: dict
    outputs: dict
    residual: float
    success: bool
    nfev: int
    message: str = ""
    x: np.ndarray = field(default=None, repr=False)
    u: np.ndarray = field(default=None, repr=False)
