"""Elementwise math blocks: gain, sum, product.

Their ports take the shape of what is wired to them.
"""

from __future__ import annotations

import numpy as np

from ..core.block import Block
from ..core.errors import ParameterError, ShapeError
from ..core.params import finite_array


class Gain(Block):
    """``y = k * u`` (elementwise, ``k`` broadcast against ``u``).

    Ports
    -----
    u : in, any shape
    y : out, same shape as ``u``

    Parameters
    ----------
    k : float or array
        The gain; a numeric parameter (``"name.k"``), changeable between and
        during runs without a rebuild.
    """

    def __init__(self, k=1.0):
        super().__init__()
        self.declare_inherited()   # sample time of its drivers
        self.declare_parameter("k", finite_array(k, "Gain", "k"), doc="gain")
        self.declare_input("u")
        self.declare_output("y")

    def configure(self, inputs):
        shape = inputs["u"].shape
        try:
            out = np.broadcast_shapes(shape, self.k.shape)
        except ValueError:
            raise ShapeError("gain does not broadcast against the input",
                             block="Gain", port="u", expected=self.k.shape,
                             found=shape) from None
        self.redeclare_output("y", out, "float64")

    def output(self, t, x, u, xp):
        return {"y": self.k * u["u"]}


class Sum(Block):
    """Signed sum of several inputs: ``y = s_1 u_1 + s_2 u_2 + ...``.

    Ports
    -----
    u0, u1, ... : in, same shape
    y : out

    Parameters
    ----------
    signs : str
        One ``+`` or ``-`` per input, e.g. ``"+-"`` for ``u0 - u1``.
    """

    def __init__(self, signs="++"):
        super().__init__()
        self.declare_inherited()   # sample time of its drivers
        if not signs or any(c not in "+-" for c in signs):
            raise ParameterError("signs must be a string of '+' and '-'",
                                 block="Sum", param="signs", found=signs)
        self.signs = [1.0 if c == "+" else -1.0 for c in signs]
        for j in range(len(signs)):
            self.declare_input(f"u{j}")
        self.declare_output("y")

    def configure(self, inputs):
        shapes = {inputs[f"u{j}"].shape for j in range(len(self.signs))}
        if len(shapes) != 1:
            raise ShapeError("all inputs of a Sum must have the same shape",
                             block="Sum", found=sorted(shapes))
        self.redeclare_output("y", shapes.pop(), "float64")

    def output(self, t, x, u, xp):
        y = self.signs[0] * u["u0"]
        for j in range(1, len(self.signs)):
            y = y + self.signs[j] * u[f"u{j}"]
        return {"y": y}


class Product(Block):
    """Elementwise product (or quotient) of inputs: ``ops="**/"`` means
    ``u0 * u1 / u2``.

    Ports
    -----
    u0, u1, ... : in, broadcastable shapes
    y : out, broadcast shape
    """

    def __init__(self, ops="**"):
        super().__init__()
        self.declare_inherited()   # sample time of its drivers
        if not ops or any(c not in "*/" for c in ops):
            raise ParameterError("ops must be a string of '*' and '/'",
                                 block="Product", param="ops", found=ops)
        self.ops = ops
        for j in range(len(ops)):
            self.declare_input(f"u{j}")
        self.declare_output("y")

    def configure(self, inputs):
        try:
            out = np.broadcast_shapes(*(inputs[f"u{j}"].shape for j in range(len(self.ops))))
        except ValueError:
            raise ShapeError("inputs do not broadcast", block="Product",
                             found=[inputs[f"u{j}"].shape for j in range(len(self.ops))]
                             ) from None
        self.redeclare_output("y", out, "float64")

    def output(self, t, x, u, xp):
        y = u["u0"] if self.ops[0] == "*" else 1.0 / u["u0"]
        for j in range(1, len(self.ops)):
            y = y * u[f"u{j}"] if self.ops[j] == "*" else y / u[f"u{j}"]
        return {"y": y}
