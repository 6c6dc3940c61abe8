"""Blimp: 4-DoF (x, y, z, yaw) lighter-than-air vehicle.

Roll and pitch are neglected (the gondola's pendulum keeps the hull level),
the centre of gravity is below the centre of volume on the same vertical,
and the added-mass matrix is diagonal. With body velocities
``nu = (u, v, w, r)`` (surge, sway, heave, yaw rate) the Fossen-form model
``(M_RB + M_A) dnu/dt + C(nu) nu + D(nu) nu = tau + g`` reads::

    m_x du/dt = f_x + m_y v r - d_u(u)
    m_y dv/dt =     - m_x u r - d_v(v)
    m_z dw/dt = f_z + L       - d_w(w)
    I_z dr/dt = tau_r + (m_x - m_y) u v - d_r(r)

    dx/dt = u cos(psi) - v sin(psi)
    dy/dt = u sin(psi) + v cos(psi)
    dz/dt = w,   dpsi/dt = r

with ``m_x = m + X_u``, ``m_y = m + Y_v``, ``m_z = m + Z_w``, ``I_z =
J_z + N_r`` (rigid-body mass/inertia plus added mass/inertia, all >= 0),
net lift ``L = B - m g`` (buoyancy minus weight; 0 is neutral buoyancy),
thrust ``f_x`` (body x), ``f_z`` (vertical) and yaw torque ``tau_r``. Drag
``d_i(s) = D_i s`` (``drag="linear"``) or ``D_i |s| s`` (``"quadratic"``);
with constant ``f_x`` the terminal surge speed is ``f_x / D_u`` or
``sqrt(f_x / D_u)``.

References
----------
S. B. V. Gomes, J. G. Ramos, "Airship dynamic modeling for autonomous
operation", ICRA 1998 (6-DoF airship model, added mass, buoyancy);
T. I. Fossen, *Handbook of Marine Craft Hydrodynamics and Motion Control*
(2011), Sections 6.3 and 7.2 (C(nu) of a diagonal mass matrix, the
4-DoF reduction used here).
"""

from __future__ import annotations

import numpy as np

from ..core.block import Block
from ..core.errors import ParameterError
from ..core.params import agent_array, poses
from ..utility.angles import wrap_angle
from ._common import any_finite, limit


def blimp_rhs(yaw, nu, forces, m4, damping, net_lift=0.0, quadratic=False, xp=np):
    """Derivatives of N blimps.

    ``yaw`` (N,), ``nu`` (N, 4) = (u, v, w, r) body velocities, ``forces``
    (N, 3) = (f_x, f_z, tau_r), ``m4`` (N, 4) = (m_x, m_y, m_z, I_z) total
    mass/inertia with added mass, ``damping`` (N, 4), ``net_lift`` (N,).
    Returns ``(dposition (N, 3), dyaw (N,), dnu (N, 4))``.
    """
    u, v, w, r = nu[:, 0], nu[:, 1], nu[:, 2], nu[:, 3]
    mx, my, mz, iz = m4[:, 0], m4[:, 1], m4[:, 2], m4[:, 3]
    d = damping * (xp.abs(nu) * nu if quadratic else nu)
    du = (forces[:, 0] + my * v * r - d[:, 0]) / mx
    dv = (-mx * u * r - d[:, 1]) / my
    dw = (forces[:, 1] + net_lift - d[:, 2]) / mz
    dr = (forces[:, 2] + (mx - my) * u * v - d[:, 3]) / iz
    c, s = xp.cos(yaw), xp.sin(yaw)
    dpos = xp.stack([u * c - v * s, u * s + v * c, w], axis=-1)
    return dpos, r, xp.stack([du, dv, dw, dr], axis=-1)


class Blimp(Block):
    """N blimps (4-DoF: x, y, z, yaw) in one block.

    Ports
    -----
    thrust : in, (N, 3) [N, N, N m]
        Body-x thrust f_x, vertical thrust f_z and yaw torque tau_r (not
        direct feedthrough).
    position : out, (N, 3) [m]
    velocity : out, (N, 3) [m/s], world frame
    pose : out, (N, 3) [m, m, rad], (x, y, yaw), yaw in (-pi, pi]
    body_velocity : out, (N, 4) [m/s, m/s, m/s, rad/s], (u, v, w, r)

    State
    -----
    position (N, 3), yaw (N,), body_velocity (N, 4): continuous.

    Parameters
    ----------
    position0 : array_like, (N, 3)
    yaw0 : float or (N,), optional
    body_velocity0 : (4,) or (N, 4), optional
    mass : float or (N,)
        Rigid-body mass m [kg] (hull gas included), default 1.5.
    inertia : float or (N,)
        Yaw inertia J_z [kg m^2], default 0.2.
    added_mass : (4,) or (N, 4)
        (X_u, Y_v, Z_w, N_r) added mass [kg] and inertia [kg m^2],
        default (0.3, 1.0, 1.0, 0.1) (an elongated hull: small along x).
    net_lift : float or (N,)
        Buoyancy minus weight [N] (default 0: neutral).
    drag : {"linear", "quadratic"}
    drag_coeff : (4,) or (N, 4)
        D for (u, v, w, r), default (0.2, 0.5, 0.5, 0.05) in N s/m
        (linear) or N s^2/m^2 (quadratic) and the yaw analogues.
    thrust_max : (2,) or (N, 2), optional
        Limits on |f_x|, |f_z| [N] (default none).
    torque_max : float or (N,), optional
        Limit on |tau_r| [N m] (default none).

    Numeric parameters
    ------------------

    ``mass``, ``inertia``, ``added_mass``, ``net_lift``, ``drag_coeff``,
    ``thrust_max`` and ``torque_max`` are numeric parameters (per agent,
    shapes as above with N leading); ``drag`` (the law) is structural.

    Equations
    ---------
    See the module docstring.

    References
    ----------
    Gomes & Ramos (1998); Fossen (2011).

    Examples
    --------
    >>> import numpy as np, avblocks as av
    >>> b = av.vehicles.Blimp(np.zeros((1, 3)), mass=1.0, added_mass=(1.0, 1, 1, 0.1))
    >>> d = b.derivative(0, b.initial_state(), {"thrust": np.array([[1.0, 0, 0]])}, np)
    >>> float(d["body_velocity"][0, 0])
    0.5
    """

    def __init__(self, position0, *, yaw0=0.0, body_velocity0=0.0, mass=1.5,
                 inertia=0.2, added_mass=(0.3, 1.0, 1.0, 0.1), net_lift=0.0,
                 drag="quadratic", drag_coeff=(0.2, 0.5, 0.5, 0.05),
                 thrust_max=np.inf, torque_max=np.inf):
        super().__init__()
        name = "Blimp"
        p0 = poses(position0, name, "position0", dim=3)
        self.n = n = p0.shape[0]
        y0 = agent_array(yaw0, n, name, "yaw0")
        nu0 = agent_array(body_velocity0, n, name, "body_velocity0", (4,))
        dp = self.declare_parameter
        dp("mass", agent_array(mass, n, name, "mass", positive=True),
           bounds=(1e-12, None), unit="kg")
        dp("inertia", agent_array(inertia, n, name, "inertia", positive=True),
           bounds=(1e-12, None), unit="kg m^2")
        dp("added_mass", agent_array(added_mass, n, name, "added_mass", (4,),
                                     nonnegative=True), bounds=(0, None))
        dp("net_lift", agent_array(net_lift, n, name, "net_lift"), unit="N")
        if drag not in ("linear", "quadratic"):
            raise ParameterError("unknown drag law", block=name, param="drag",
                                 expected="'linear' or 'quadratic'", found=drag)
        self.quadratic = drag == "quadratic"
        dp("drag_coeff", agent_array(drag_coeff, n, name, "drag_coeff", (4,),
                                     nonnegative=True), bounds=(0, None))
        dp("thrust_max", limit(thrust_max, n, name, "thrust_max", (2,)),
           bounds=(0, None), allow_inf=True, unit="N")
        dp("torque_max", limit(torque_max, n, name, "torque_max"), bounds=(0, None),
           allow_inf=True, unit="N m")
        xyz = ("x", "y", "z")
        self.declare_continuous_state("position", p0, unit="m", labels=xyz)
        self.declare_continuous_state("yaw", y0, unit="rad")
        self.declare_continuous_state("body_velocity", nu0, unit="m/s, m/s, m/s, rad/s",
                                      labels=("u", "v", "w", "r"))
        self.declare_input("thrust", (n, 3), unit="N, N, N m",
                           labels=("f_x", "f_z", "tau_r"),
                           doc="body-x thrust, vertical thrust, yaw torque",
                           feedthrough=False)
        self.declare_output("position", (n, 3), unit="m", labels=xyz)
        self.declare_output("velocity", (n, 3), unit="m/s", labels=xyz, doc="world frame")
        self.declare_output("pose", (n, 3), unit="m, m, rad", labels=("x", "y", "yaw"))
        self.declare_output("body_velocity", (n, 4), unit="m/s, m/s, m/s, rad/s",
                            labels=("u", "v", "w", "r"))

    def output(self, t, x, u, xp):
        p, yaw, nu = x["position"], x["yaw"], x["body_velocity"]
        c, s = xp.cos(yaw), xp.sin(yaw)
        vel = xp.stack([nu[:, 0] * c - nu[:, 1] * s, nu[:, 0] * s + nu[:, 1] * c,
                        nu[:, 2]], axis=-1)
        pose = xp.concatenate([p[:, :2], wrap_angle(yaw, xp)[:, None]], axis=-1)
        return {"position": p, "velocity": vel, "pose": pose, "body_velocity": nu}

    def derivative(self, t, x, u, xp):
        f = u["thrust"]
        if self.param_flag("limited", xp, any_finite, "thrust_max", "torque_max"):
            lim = xp.concatenate([self.thrust_max, self.torque_max[:, None]], axis=-1)
            f = xp.clip(f, -lim, lim)
        m4 = self.added_mass + xp.stack([self.mass, self.mass, self.mass,
                                         self.inertia], axis=-1)
        dp, dyaw, dnu = blimp_rhs(x["yaw"], x["body_velocity"], f, m4,
                                  self.drag_coeff, self.net_lift, self.quadratic, xp)
        return {"position": dp, "yaw": dyaw, "body_velocity": dnu}
