"""Port and state specifications.

A :class:`Port` describes one signal: its name, its full array shape (the
agent axis first when ``agents`` is true), dtype, unit, component labels and a
short doc. Shapes may be ``None`` for ports whose shape is inherited from what
is wired to them (generic blocks such as Gain); the diagram resolves them when
it is built.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .errors import ShapeError


def _size(s):
    if isinstance(s, (bool, np.bool_)):
        raise TypeError("a size is not a bool")
    if isinstance(s, (int, np.integer)):
        return int(s)
    f = float(s)
    if f != int(f):
        raise ValueError("a size is a whole number")
    return int(f)


@dataclass(frozen=True)
class Port:
    """Specification of an input or output port (or of a state).

    Attributes
    ----------
    name : str
        Port name, a Python identifier (``pose``, ``cmd``...).
    shape : tuple of int or None
        Full array shape. With ``agents=True`` the first axis is the agent
        axis. ``None`` means "inherited from the connected signal".
    dtype : str
        NumPy dtype name (``float64``, ``bool``, ``int64``...).
    unit : str
        SI units of the components, free text (``m, m, rad``).
    labels : tuple of str
        Optional names of the components along the last axis.
    doc : str
        One line saying what the signal is.
    agents : bool
        True when the leading axis is the agent axis.
    """

    name: str
    shape: tuple | None = None
    dtype: str = "float64"
    unit: str = ""
    labels: tuple = ()
    doc: str = ""
    agents: bool = True

    def __post_init__(self):
        if not str(self.name).isidentifier():
            raise ShapeError("port name must be a Python identifier",
                             port=self.name, expected="identifier",
                             found=repr(self.name))
        if self.shape is not None:
            try:
                shape = tuple(_size(s) for s in self.shape)
            except (TypeError, ValueError, OverflowError):
                shape = None
            if shape is None or any(s < 0 for s in shape):
                raise ShapeError("a port shape is a tuple of whole numbers >= 0 "
                                 "(a negative agent count?)", port=self.name,
                                 expected="e.g. (n, 3) with n >= 0",
                                 found=repr(self.shape)[:60])
            object.__setattr__(self, "shape", shape)
        try:
            object.__setattr__(self, "dtype", np.dtype(self.dtype).name)
        except TypeError:
            raise ShapeError("unknown dtype", port=self.name,
                             found=repr(self.dtype)[:40]) from None

    @property
    def n(self) -> int | None:
        """Number of agents (length of the leading axis), if known."""
        if self.shape is None or not self.agents or len(self.shape) == 0:
            return None
        return self.shape[0]

    def with_shape(self, shape, dtype=None) -> Port:
        return replace(self, shape=None if shape is None else tuple(shape),
                       dtype=self.dtype if dtype is None else np.dtype(dtype).name)

    def describe(self) -> str:
        s = "?" if self.shape is None else "(" + ", ".join(map(str, self.shape)) + ")"
        return f"{s} {self.dtype}"


def check_compatible(src: Port, dst: Port, *, src_name: str, dst_name: str):
    """Raise :class:`ShapeError` if output ``src`` cannot drive input ``dst``."""
    if src.shape is None or dst.shape is None:
        return
    if src.shape != dst.shape:
        if (src.agents and dst.agents and len(src.shape) == len(dst.shape)
                and len(src.shape) > 0 and src.shape[1:] == dst.shape[1:]):
            raise ShapeError(
                f"agent count mismatch: {src_name} carries {src.shape[0]} agents "
                f"but {dst_name} expects {dst.shape[0]}",
                block=dst_name.rsplit(".", 1)[0], port=dst.name,
                expected=dst.shape, found=src.shape,
                hint="give both blocks the same number of agents, or insert a "
                     "Select/Gather block to pick agents")
        raise ShapeError(
            f"shape mismatch wiring {src_name} -> {dst_name}",
            block=dst_name.rsplit(".", 1)[0], port=dst.name,
            expected=dst.shape, found=src.shape)
    if src.dtype != dst.dtype and not np.can_cast(src.dtype, dst.dtype, "same_kind"):
        raise ShapeError(
            f"dtype mismatch wiring {src_name} -> {dst_name}",
            block=dst_name.rsplit(".", 1)[0], port=dst.name,
            expected=dst.dtype, found=src.dtype)
