"""Linear analysis of diagrams: linearisation, trim, python-control.

    m = av.linearize(d, at={"fleet.pose": p}, inputs=["form.ref"],
                     outputs=["form.error"])          # exact, through JAX
    m.poles(); sys = m.to_control()                   # control.StateSpace
    eq = av.trim(d, outputs={"quad.position": [[0, 0, 1]]},
                 inputs=["quad.wrench"])              # an equilibrium
    lin = av.analysis.Linearizer(d, inputs=[...], outputs=[...])
    [lin(params={"form.k_l": k}).poles() for k in gains]   # compiled once

:func:`linearize` (continuous-time models; sampled ones for discrete and
mixed diagrams: the simulator's map over one base period), :func:`trim`
(SciPy's least squares on the exact Jacobians), :func:`to_control`
(python-control, the ``analysis`` extra). The Jacobians come from the
compiled engine's own traced functions (the ``jax`` extra). See
docs/linear-analysis.md.
"""

from .control import control_name, to_control
from .linearize import Linearizer, linearize
from .model import LinearModel, TrimResult
from .names import entry_names
from .trim import TrimError, trim

__all__ = ["linearize", "Linearizer", "LinearModel", "trim", "TrimResult", "TrimError",
           "to_control", "control_name", "entry_names"]
