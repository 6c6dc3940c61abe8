"""Flight limits, checked on every command before anything is sent.

Two kinds of limit:

* **Shaping** (the command is changed, the run goes on): the speed is
  scaled down to ``speed_max``; the change of the velocity set-point from
  one sent command to the next is limited to ``accel_max * dt`` (per
  vehicle, as a vector); a velocity that would carry a vehicle through a
  face of the geofence box within ``lookahead`` seconds is cut, per axis,
  so that the vehicle stops at the face.
* **Breaches** (the fail-safe lands every vehicle and ends the run): a
  vehicle outside the geofence box by more than ``fence_margin``, two
  vehicles closer than ``min_separation``. The same tests, with no margin,
  refuse a start in the pre-flight check.

All functions are vectorized over vehicles (vehicles on the leading axis)
and return new arrays; the messages name the vehicles and the numbers.
"""

from __future__ import annotations

import numpy as np

from ...core.errors import ParameterError


def _fence(geofence):
    if geofence is None:
        return None
    g = np.asarray(geofence, float).ravel()
    if g.shape == (4,):
        g = np.r_[g, -np.inf, np.inf]
    if (g.shape != (6,) or np.isnan(g).any()
            or not np.all(g[0::2] < g[1::2])):
        raise ParameterError("geofence must be (xmin, xmax, ymin, ymax[, zmin, zmax]) "
                             "with min < max", param="geofence", found=geofence)
    return g


class FlightLimits:
    """Speed, acceleration, geofence and separation limits of N vehicles.

    Parameters
    ----------
    n : int
        Number of vehicles.
    speed_max : float or (N,)
        Largest speed sent [m/s] (inf: none).
    accel_max : float or (N,)
        Largest change of the velocity set-point per second [m/s^2]
        (inf: none).
    geofence : (xmin, xmax, ymin, ymax[, zmin, zmax]), optional
        Box in the world frame [m] every vehicle must stay in.
    min_separation : float
        Smallest distance allowed between two vehicles [m] (0: none).
    lookahead : float
        Seconds ahead the geofence cut looks [s].
    fence_margin : float
        In flight, how far outside the box counts as a breach [m] (the
        shaping keeps vehicles inside; this tolerates overshoot).
    """

    def __init__(self, n, speed_max=np.inf, accel_max=np.inf, geofence=None,
                 min_separation=0.0, lookahead=1.0, fence_margin=0.2):
        self.n = int(n)
        for name, v in (("speed_max", speed_max), ("accel_max", accel_max)):
            a = np.broadcast_to(np.asarray(v, float), (self.n,)).copy()
            if np.isnan(a).any() or (a <= 0).any():
                raise ParameterError(f"{name} must be positive (inf for none)",
                                     param=name, found=v)
            setattr(self, name, a)
        self.geofence = _fence(geofence)
        for name, v in (("min_separation", min_separation), ("lookahead", lookahead),
                        ("fence_margin", fence_margin)):
            if not (np.isfinite(v) and v >= 0):
                raise ParameterError(f"{name} must be a finite number >= 0", param=name,
                                     found=v)
        self.min_separation = float(min_separation)
        self.lookahead = max(float(lookahead), 1e-3)
        self.fence_margin = float(fence_margin)

    # ---------------------------------------------------------------- shaping
    def shape(self, v, v_prev, dt, position):
        """The velocity to send (N, 3) for the wanted ``v`` (N, 3), given the
        last sent ``v_prev`` (N, 3), the time since it ``dt`` [s] and the
        vehicles' ``position`` (N, 3)."""
        v = np.asarray(v, float)
        sp = np.linalg.norm(v, axis=1)
        v = v * np.minimum(1.0, self.speed_max / np.maximum(sp, 1e-300))[:, None]
        if v_prev is not None and np.isfinite(self.accel_max).any() and dt > 0:
            dv = v - v_prev
            m = np.linalg.norm(dv, axis=1)
            step = self.accel_max * dt
            v = v_prev + dv * np.minimum(1.0, step / np.maximum(m, 1e-300))[:, None]
        if self.geofence is not None:
            p = np.asarray(position, float)
            lo, hi = self.geofence[0::2], self.geofence[1::2]
            h = self.lookahead
            # fastest speed along each axis that stops at the face within h
            v = np.clip(v, np.minimum((lo - p) / h, 0.0), np.maximum((hi - p) / h, 0.0))
        return v

    # ---------------------------------------------------------------- breaches
    def outside(self, names, position, margin=0.0):
        """``["cf2 at (3.10, 0.00, 1.00) is outside the geofence ..."]``."""
        if self.geofence is None:
            return []
        p = np.asarray(position, float)
        lo, hi = self.geofence[0::2] - margin, self.geofence[1::2] + margin
        bad = ~np.all((p >= lo) & (p <= hi), axis=1)
        box = ", ".join(f"{a:g}..{b:g}" for a, b in zip(self.geofence[0::2],
                                                          self.geofence[1::2]))
        return [f"{names[i]} at ({p[i, 0]:.2f}, {p[i, 1]:.2f}, {p[i, 2]:.2f}) is outside "
                f"the geofence (x, y, z in {box})" for i in np.nonzero(bad)[0]]

    def too_close(self, names, position):
        """``["cf1-cf2 0.12 m apart (min_separation 0.3 m)"]``."""
        if self.min_separation <= 0 or self.n < 2:
            return []
        p = np.asarray(position, float)
        dist = np.linalg.norm(p[:, None] - p[None], axis=-1)
        i, j = np.nonzero(np.triu(dist < self.min_separation, 1))
        # centimetres rounded down: 0.7996 m under a 0.8 m minimum reads 0.79,
        # never "0.80 m apart (min_separation 0.8 m)" (a CI run printed that)
        shown = np.floor(dist * 100 + 1e-9) / 100
        return [f"{names[a]}-{names[b]} {shown[a, b]:.2f} m apart (min_separation "
                f"{self.min_separation:g} m)" for a, b in zip(i, j)]

    def breaches(self, names, position):
        """Every in-flight breach (outside the fence by more than the margin,
        too close), as messages naming the vehicles."""
        return self.outside(names, position, self.fence_margin) + \
            self.too_close(names, position)

    def breaching(self, position):
        """(N,) bool: the vehicles in a breach (see :meth:`breaches`)."""
        p = np.asarray(position, float)
        bad = np.zeros(len(p), bool)
        if self.geofence is not None:
            m = self.fence_margin
            lo, hi = self.geofence[0::2] - m, self.geofence[1::2] + m
            bad |= ~np.all((p >= lo) & (p <= hi), axis=1)
        if self.min_separation > 0 and len(p) > 1:
            dist = np.linalg.norm(p[:, None] - p[None], axis=-1)
            close = dist < self.min_separation
            np.fill_diagonal(close, False)
            bad |= close.any(axis=1)
        return bad
