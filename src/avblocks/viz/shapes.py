"""Vehicle drawings in the body frame and their vectorized placement.

A :class:`Drawing` is a stack of polygons ("parts") in the body frame of a
vehicle at unit size: x forward, y to the left, origin at the point the pose
refers to. :meth:`Drawing.place` puts the drawing at N poses at once (one
array expression, no loop over agents) and returns ``(N * P, M, 2)`` world
vertices ready for :meth:`matplotlib.collections.PolyCollection.set_verts`.

Built-in drawings (:data:`DRAWINGS`): ``arrow`` (the default), ``unicycle``
(triangle), ``robot`` (disc with a heading bar), ``car`` (body and four
wheels, front wheels turned by a steering signal, origin at the rear axle),
``quadrotor`` (top view: X arms and four rotor discs), ``blimp`` (ellipse
with a tail fin).

>>> import numpy as np
>>> d = drawing("unicycle")
>>> d.place(np.array([[1.0, 2.0, np.pi / 2]]), 2.0)[0, 0].round(6)   # the nose
array([1., 3.])
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass

import numpy as np

from ..core.errors import ParameterError


def _circle(r, cx=0.0, cy=0.0, m=20):
    a = np.linspace(0, 2 * np.pi, m, endpoint=False)
    return np.stack([cx + r * np.cos(a), cy + r * np.sin(a)], axis=-1)


def _rect(x0, x1, y0, y1):
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], float)


@dataclass(frozen=True, eq=False)
class Drawing:
    """Polygons of one vehicle in its body frame, at unit size.

    Attributes
    ----------
    parts : ndarray, shape (P, M, 2)
        Vertices of each part (shorter parts padded by repeating their last
        vertex).
    fixed : ndarray of bool, shape (P,)
        Parts drawn in a fixed dark colour instead of the agent's colour
        (wheels, rotor arms).
    steer : ndarray of bool, shape (P,)
        Parts turned by the steering angle about their own centre (front
        wheels).
    """

    parts: np.ndarray
    fixed: np.ndarray
    steer: np.ndarray

    @classmethod
    def from_parts(cls, parts, fixed=None, steer=None) -> Drawing:
        """Build from a list of ``(M_i, 2)`` vertex arrays."""
        polys = [np.asarray(p, float) for p in parts]
        for p in polys:
            if p.ndim != 2 or p.shape[1] != 2 or len(p) < 2:
                raise ParameterError("a drawing part must be an (M, 2) vertex array",
                                     param="drawing", expected="(M, 2), M >= 2",
                                     found=p.shape)
        m = max(len(p) for p in polys)
        arr = np.stack([np.concatenate([p, np.repeat(p[-1:], m - len(p), 0)])
                        for p in polys])
        n = len(polys)
        fx = np.zeros(n, bool) if fixed is None else np.asarray(fixed, bool)
        st = np.zeros(n, bool) if steer is None else np.asarray(steer, bool)
        return cls(arr, fx, st)

    @property
    def n_parts(self) -> int:
        return self.parts.shape[0]

    @property
    def radius(self) -> float:
        """Largest distance of a vertex from the origin, at unit size."""
        return float(np.max(np.hypot(self.parts[..., 0], self.parts[..., 1])))

    def place(self, pose, size=1.0, steer=None) -> np.ndarray:
        """World vertices ``(N * P, M, 2)`` of the drawing at ``pose`` (N, 3).

        ``size`` is a scalar or ``(N,)``; ``steer`` an optional ``(N,)``
        steering angle (radians) for the steered parts.
        """
        pose = np.asarray(pose, float)
        k = pose.shape[0]
        size = np.broadcast_to(np.asarray(size, float), (k,))
        b = self.parts[None, :, :, :] * size[:, None, None, None]     # (N,P,M,2)
        if steer is not None and self.steer.any():
            d = np.asarray(steer, float).reshape(k)
            sp = b[:, self.steer]                                        # (N,S,M,2)
            c = sp.mean(axis=2, keepdims=True)
            cd, sd = np.cos(d)[:, None, None], np.sin(d)[:, None, None]
            rx, ry = sp[..., 0] - c[..., 0], sp[..., 1] - c[..., 1]
            b = b.copy()
            b[:, self.steer] = np.stack([cd * rx - sd * ry, sd * rx + cd * ry],
                                        axis=-1) + c
        c = np.cos(pose[:, 2])[:, None, None]
        s = np.sin(pose[:, 2])[:, None, None]
        bx, by = b[..., 0], b[..., 1]
        wx = c * bx - s * by + pose[:, 0, None, None]
        wy = s * bx + c * by + pose[:, 1, None, None]
        return np.stack([wx, wy], axis=-1).reshape(k * self.n_parts, -1, 2)


def _builtin():
    arrow = Drawing.from_parts([[[0.5, 0.0], [0.05, 0.3], [0.05, 0.09], [-0.5, 0.09],
                                 [-0.5, -0.09], [0.05, -0.09], [0.05, -0.3]]])
    tri = Drawing.from_parts([[[0.5, 0.0], [-0.5, 0.32], [-0.5, -0.32]]])
    robot = Drawing.from_parts([_circle(0.5, m=24), _rect(0.0, 0.5, -0.05, 0.05)],
                               fixed=[False, True])
    wl, ww = 0.2, 0.08
    car = Drawing.from_parts(
        [_rect(-0.2, 0.8, -0.25, 0.25),
         _rect(-wl / 2, wl / 2, 0.22, 0.22 + ww), _rect(-wl / 2, wl / 2, -0.22 - ww, -0.22),
         _rect(0.6 - wl / 2, 0.6 + wl / 2, 0.22, 0.22 + ww),
         _rect(0.6 - wl / 2, 0.6 + wl / 2, -0.22 - ww, -0.22),
         [[0.8, 0.0], [0.62, 0.1], [0.62, -0.1]]],
        fixed=[False, True, True, True, True, True],
        steer=[False, False, False, True, True, False])
    h = 0.5 / np.sqrt(2)
    arm = 0.03
    quad = Drawing.from_parts(
        [np.array([[-h - arm, -h + arm], [-h + arm, -h - arm], [h + arm, h - arm],
                   [h - arm, h + arm]]) * 0.9,
         np.array([[-h - arm, h - arm], [-h + arm, h + arm], [h + arm, -h + arm],
                   [h - arm, -h - arm]]) * 0.9,
         _circle(0.17, h * 0.9, h * 0.9), _circle(0.17, h * 0.9, -h * 0.9),
         _circle(0.17, -h * 0.9, h * 0.9), _circle(0.17, -h * 0.9, -h * 0.9),
         [[0.2, 0.0], [-0.08, 0.1], [-0.08, -0.1]]],
        fixed=[True, True, False, False, False, False, True])
    blimp = Drawing.from_parts([np.stack([0.5 * np.cos(a := np.linspace(0, 2 * np.pi, 28,
                                                                          endpoint=False)),
                                          0.2 * np.sin(a)], -1),
                                [[-0.3, 0.0], [-0.55, 0.22], [-0.5, 0.0], [-0.55, -0.22]]],
                               fixed=[False, True])
    return {"arrow": arrow, "unicycle": tri, "triangle": tri, "robot": robot,
            "disc": robot, "car": car, "ackermann": car, "quadrotor": quad,
            "blimp": blimp}


#: Built-in drawings by name.
DRAWINGS: dict[str, Drawing] = _builtin()


def drawing(spec) -> Drawing | object:
    """Turn a drawing spec into a :class:`Drawing` (or keep a pose callable).

    ``spec`` is a built-in name (:data:`DRAWINGS`), a :class:`Drawing`, an
    ``(M, 2)`` vertex array or a list of them (body frame, unit size), a
    function of no arguments returning such vertices, or a function of one
    argument ``poses`` (K, 3) returning either world vertices ``(K, M, 2)``
    or a Matplotlib collection; the last kind is returned unchanged and is
    called at every frame.
    """
    if isinstance(spec, Drawing):
        return spec
    if isinstance(spec, str):
        try:
            return DRAWINGS[spec.lower()]
        except KeyError:
            raise ParameterError("unknown drawing", param="drawing",
                                 expected=sorted(DRAWINGS), found=spec) from None
    if callable(spec):
        try:
            nreq = sum(1 for p in inspect.signature(spec).parameters.values()
                       if p.default is p.empty and p.kind in (p.POSITIONAL_ONLY,
                                                              p.POSITIONAL_OR_KEYWORD))
        except (TypeError, ValueError):
            nreq = 1
        if nreq == 0:
            return drawing(spec())
        return spec
    try:
        arr = np.asarray(spec, float)
    except ValueError:                      # ragged: a list of parts
        return Drawing.from_parts(list(spec))
    if arr.ndim == 2:
        return Drawing.from_parts([arr])
    if arr.ndim == 3:
        return Drawing.from_parts(list(arr))
    raise ParameterError("cannot make a drawing of this", param="drawing",
                         expected="name, (M, 2) vertices, list of them or a callable",
                         found=type(spec).__name__)
