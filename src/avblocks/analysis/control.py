"""Linear models as python-control systems (the ``analysis`` extra).

:func:`to_control` gives a :class:`control.StateSpace` with the model's
state, input and output names, so python-control's tools work on a
linearised diagram as on any LTI model: ``control.poles``,
``control.step_response``, ``control.bode_plot``, ``control.root_locus``,
``control.lqr``, ``control.feedback``. A sampled model keeps its period as
the system's ``dt``.

python-control does not allow ``.`` in signal names (in ``interconnect`` it
separates a system's name from its signal), so the names are carried over
with ``/`` in place of ``.``: the model's ``"fleet.pose[1].theta"`` is the
system's ``"fleet/pose[1]/theta"`` (:func:`control_name`), for states,
inputs and outputs alike.

Reference: python-control (``control`` 0.10), ``StateSpace`` and its
signal names; R. M. Murray et al., "python-control: a Python package for
control systems", IEEE CDC 2021.
"""

from __future__ import annotations

from ..core.errors import AvError


def control_module():
    """The ``control`` package, or an AvError telling how to install it."""
    try:
        import control
    except ImportError as e:
        raise AvError("converting to python-control needs the 'control' package",
                      hint="pip install 'avblocks[analysis]'") from e
    return control


def control_name(name: str) -> str:
    """The python-control name of a model's entry: ``.`` becomes ``/``.

    >>> control_name("fleet.pose[1].theta")
    'fleet/pose[1]/theta'
    """
    return str(name).replace(".", "/")


def to_control(model, name=None):
    """``model`` (a :class:`~avblocks.analysis.LinearModel`) as a
    :class:`control.StateSpace` named ``name``, with its states, inputs
    and outputs named as in the model, ``/`` for ``.``
    (:func:`control_name`: ``"fleet/pose[1]/theta"``).

    Examples
    --------
    >>> import numpy as np, avblocks as av
    >>> d = av.Diagram()
    >>> src = d.add(av.blocks.Constant([[0.0]]), name="src")
    >>> x = d.add(av.blocks.Integrator([[0.0]]), name="x")
    >>> _ = d.connect(src.y, x.u)
    >>> sys = av.linearize(d, inputs=["x.u"], outputs=["x.y"]).to_control("plant")
    >>> sys.input_labels, sys.output_labels, sys.state_labels
    (['x/u[0][0]'], ['x/y[0][0]'], ['x/x[0][0]'])
    """
    control = control_module()
    return control.ss(model.A, model.B, model.C, model.D, model.dt,
                      states=[control_name(s) for s in model.states],
                      inputs=[control_name(s) for s in model.inputs],
                      outputs=[control_name(s) for s in model.outputs], name=name)
