"""Following a moving target seen by a sensor: an alpha-beta filter on the
measured target position and a velocity law with feed-forward
(:class:`TrackingController`, the drone of the visual-tracking case study,
AVLib paper Sec. IV.C).

Equations
---------
At each sample (period ``T``), with the filtered target ``(p, v)``
(position and velocity in the plane) and a measurement ``z``:

    predict     p- = p + v T
    innovation  r = z - p-
    if valid:   p = p- + alpha r,   v = v + (beta / T) r
    else:       p = p-            (coast on the prediction)

the first valid measurement initializes ``p = z, v = 0``. The follower at
``x`` is commanded

    v_xy = sat_{v_max}(v + k_p (p - x_xy)),   v_z = k_z (altitude - x_z).

The velocity feed-forward ``v`` removes the steady lag ``V / k_p`` that a
pure proportional law leaves behind a target moving at speed ``V``.

References: T. R. Kalata, "The tracking index: a generalized parameter for
alpha-beta and alpha-beta-gamma target trackers", IEEE Trans. Aerospace and
Electronic Systems 20(2), 1984; the AVLib paper, Sec. IV.C (a quadrotor
follows a ground vehicle by its camera).
"""

from __future__ import annotations

import numpy as np

from ..core.block import Block
from ..core.errors import ParameterError
from ..core.params import positive_scalar


def alpha_beta_step(est, seen, z, valid, period, alpha, beta, xp=np):
    """One alpha-beta filter step: ``est`` (N, 4) = (x, y, vx, vy), ``seen``
    (N,) bool (a measurement came before), ``z`` (N, 2), ``valid`` (N,)
    bool; returns the new (N, 4) estimate (see the module's equations)."""
    p_pred = est[:, :2] + period * est[:, 2:]
    r = z - p_pred
    ok = valid[:, None]
    p = xp.where(ok, p_pred + alpha * r, p_pred)
    v = xp.where(ok, est[:, 2:] + beta / period * r, est[:, 2:])
    first = (valid & ~seen)[:, None]
    p = xp.where(first, z, p)
    v = xp.where(first, 0.0, v)
    return xp.concatenate([p, v], axis=1)


def follow_velocity(estimate, position, k_p, k_z, altitude, v_max, xp=np):
    """Velocity set-point (N, 3) toward the filtered target ``estimate``
    (N, 4) from ``position`` (N, 3) (see the module's equations)."""
    vxy = estimate[:, 2:] + k_p * (estimate[:, :2] - position[:, :2])
    nv = xp.sqrt(xp.sum(vxy * vxy, axis=1, keepdims=True))
    vxy = vxy * xp.minimum(1.0, v_max / xp.maximum(nv, 1e-12))
    vz = k_z * (altitude - position[:, 2:3])
    return xp.concatenate([vxy, vz], axis=1)


class TrackingController(Block):
    """Follow a measured target: an alpha-beta filter and a velocity law with feed-forward.

    A discrete block at the sensor's rate (e.g. a camera's), between a
    measurement of the target (e.g. ``interfaces.vision.GroundPointEstimator``)
    and a velocity-controlled vehicle (e.g.
    ``vehicles.VelocityControlledQuadrotor``).

    Ports
    -----
    point : in, (N, 3) [m]
        Measured target point (x, y used).
    valid : in, (N,) bool
        Whether this sample's measurement is fresh.
    position : in, (N, 3) [m]
        The follower's position.
    velocity : out, (N, 3) [m/s]
        Velocity set-point (world frame).
    estimate : out, (N, 4)
        Filtered target: x, y [m], vx, vy [m/s].

    State
    -----
    est : discrete (N, 4), the filtered target; seen : discrete (N,) bool.

    Parameters
    ----------
    n : int
        Number of followers.
    period : float
        Sample period T [s] (the sensor's).
    k_p : float
        Horizontal position gain [1/s].
    k_z : float
        Altitude gain [1/s].
    altitude : float
        Altitude to hold [m].
    v_max : float
        Largest horizontal speed command [m/s].
    alpha : float
        Position gain of the filter, 0 < alpha <= 1.
    beta : float
        Velocity gain of the filter, 0 < beta <= 2.
    start : array_like, (N, 2) or (N, 3), optional
        Estimate before the first measurement (default: the origin).

    Numeric parameters
    ------------------

    ``k_p``, ``k_z``, ``altitude``, ``v_max``, ``alpha``, ``beta``;
    ``period`` is structural (the sample time).

    Equations
    ---------
    See :mod:`avblocks.controllers.target_tracking`: predict
    ``p- = p + v T``, ``r = z - p-``; if valid ``p = p- + alpha r``,
    ``v = v + beta r / T``, else ``p = p-``; the first valid measurement
    sets ``p = z, v = 0``. Then ``v_xy = v + k_p (p - x_xy)`` (norm clipped
    to ``v_max``), ``v_z = k_z (altitude - x_z)``.

    References
    ----------
    T. R. Kalata, IEEE Trans. Aerospace and Electronic Systems 20(2), 1984
    (the alpha-beta tracker); AVLib paper, Sec. IV.C.
    """

    update_uses_outputs = True
    example = {"n": "$agents", "period": 0.1}

    def __init__(self, n, period, *, k_p=1.2, k_z=1.0, altitude=4.0, v_max=3.0,
                 alpha=0.6, beta=0.15, start=None):
        super().__init__()
        name = "TrackingController"
        self.n = n = int(n)
        self.T = positive_scalar(period, name, "period")
        dp = self.declare_parameter
        dp("k_p", positive_scalar(k_p, name, "k_p"), bounds=(1e-12, None), unit="1/s")
        dp("k_z", positive_scalar(k_z, name, "k_z"), bounds=(1e-12, None), unit="1/s")
        dp("altitude", float(altitude), (), unit="m")
        dp("v_max", positive_scalar(v_max, name, "v_max"), bounds=(1e-12, None),
           unit="m/s")
        dp("alpha", float(alpha), (), bounds=(1e-12, 1.0))
        dp("beta", float(beta), (), bounds=(1e-12, 2.0))
        self.declare_periodic(self.T)
        est0 = np.zeros((n, 4))
        if start is not None:
            s = np.asarray(start, float)
            if s.ndim != 2 or len(s) != n or s.shape[1] < 2 or not np.all(np.isfinite(s)):
                raise ParameterError("start must be one finite point per follower",
                                     block=name, param="start",
                                     expected=f"({n}, 2) or ({n}, 3)", found=np.shape(start))
            est0[:, :2] = s[:, :2]
        self.declare_input("point", (n, 3), unit="m")
        self.declare_input("valid", (n,), "bool")
        self.declare_input("position", (n, 3), unit="m")
        self.declare_discrete_state("est", est0)
        self.declare_discrete_state("seen", np.zeros(n, bool))
        self.declare_output("velocity", (n, 3), unit="m/s", labels=("x", "y", "z"))
        self.declare_output("estimate", (n, 4), labels=("x", "y", "vx", "vy"))

    def output(self, t, x, u, xp):
        est = alpha_beta_step(x["est"], x["seen"], u["point"][:, :2], u["valid"], self.T,
                              self.alpha, self.beta, xp)
        vel = follow_velocity(est, u["position"], self.k_p, self.k_z, self.altitude,
                              self.v_max, xp)
        return {"velocity": vel, "estimate": est}

    def update(self, t, x, u, xp, y):
        return {"est": y["estimate"], "seen": x["seen"] | u["valid"]}
