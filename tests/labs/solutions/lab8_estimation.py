"""Reference solution of lab 8 (kept with the tests, not in the template).

Lab 8: localisation with an extended Kalman filter. Write `ekf_predict`,
`ekf_correct` and MyEKF.output / MyEKF.update, then run `avblocks lab
check 8 lab8_estimation.py`.

N unicycle robots, pose x = (x, y, theta), each measuring the range and the
bearing of L known landmarks every dt seconds.

Prediction over one step, the command (v, omega) held:

    x+ = x + dt (v cos theta, v sin theta, omega)    (theta wrapped into (-pi, pi])
    P+ = F P F^T + R(theta) diag(q^2) R(theta)^T

F = d x+ / d x (the Jacobian: the identity plus the derivatives in theta);
q = (forward, lateral, heading) standard deviations of the step's noise in
the robot's own frame, rotated into the world by R(theta) =
[[cos, -sin, 0], [sin, cos, 0], [0, 0, 1]] at the heading theta the step
starts from.

Correction with the landmarks m_l (stack the 2 L measurements, range then
bearing for each landmark):

    h_l(x) = ( |m_l - p|,  wrap(atan2(m_ly - y, m_lx - x) - theta) )
    H = d h / d x,   S = H P H^T + diag(r^2, ..., r^2),   K = P H^T S^-1
    x+ = x + K wrap(z - h(x))     (wrap the bearing rows of the innovation)
    P+ = (I - K H) P              (or the Joseph form)

Return symmetric covariances: rounding makes F P F^T and (I - K H) P
slightly asymmetric, so end each step with (P + P^T) / 2.

Rules of the library: the agent axis comes first (batched matrices: (N, 3,
3); `@`, xp.swapaxes, xp.linalg.solve work on such stacks), compute with
`xp`, never loop over robots, never write into the inputs.
"""

import numpy as np

import avblocks as av


def ekf_predict(mean, cov, cmd, dt, q, xp=np):
    """One prediction step for N robots: {"mean": (N, 3), "cov": (N, 3, 3)}.

    mean (N, 3) [m, m, rad]; cov (N, 3, 3); cmd (N, 2) [m/s, rad/s]; dt [s];
    q (3,) noise standard deviations in the robot's frame [m, m, rad].
    """
    th, v, w = mean[:, 2], cmd[:, 0], cmd[:, 1]
    c, s = xp.cos(th), xp.sin(th)
    new = xp.stack([mean[:, 0] + dt * v * c, mean[:, 1] + dt * v * s,
                    av.utility.wrap_angle(th + dt * w, xp)], axis=-1)
    zero, one = xp.zeros_like(th), xp.ones_like(th)
    jac = xp.stack([xp.stack([one, zero, -dt * v * s], axis=-1),
                    xp.stack([zero, one, dt * v * c], axis=-1),
                    xp.stack([zero, zero, one], axis=-1)], axis=-2)          # (N, 3, 3)
    rot = xp.stack([xp.stack([c, -s, zero], axis=-1), xp.stack([s, c, zero], axis=-1),
                    xp.stack([zero, zero, one], axis=-1)], axis=-2)
    noise = rot @ xp.diag(xp.asarray(q) ** 2) @ xp.swapaxes(rot, -1, -2)
    p = jac @ cov @ xp.swapaxes(jac, -1, -2) + noise
    return {"mean": new, "cov": (p + xp.swapaxes(p, -1, -2)) / 2}


def ekf_correct(mean, cov, z, landmarks, r, xp=np):
    """One correction for N robots: {"mean": (N, 3), "cov": (N, 3, 3)}.

    mean (N, 3), cov (N, 3, 3): the prediction; z (N, L, 2): range [m] and
    bearing [rad] of each landmark; landmarks (L, 2) [m]; r (2,) standard
    deviations of a range [m] and a bearing [rad].
    """
    n, m = z.shape[0], z.shape[1]
    d = landmarks[None, :, :] - mean[:, None, :2]                    # (N, L, 2): m - p
    dx, dy = d[..., 0], d[..., 1]
    q2 = dx * dx + dy * dy
    rho = xp.sqrt(q2)
    zhat = xp.stack([rho, av.utility.wrap_angle(xp.arctan2(dy, dx) - mean[:, None, 2], xp)],
                    axis=-1)
    innov = z - zhat
    innov = xp.stack([innov[..., 0], av.utility.wrap_angle(innov[..., 1], xp)], axis=-1)
    innov = xp.reshape(innov, (n, 2 * m))                            # range, bearing, ...
    zero = xp.zeros_like(rho)
    h_range = xp.stack([-dx / rho, -dy / rho, zero], axis=-1)        # (N, L, 3)
    h_bearing = xp.stack([dy / q2, -dx / q2, zero - 1.0], axis=-1)
    jac = xp.reshape(xp.stack([h_range, h_bearing], axis=2), (n, 2 * m, 3))
    noise = xp.diag(xp.tile(xp.asarray(r) ** 2, m))
    s = jac @ cov @ xp.swapaxes(jac, -1, -2) + noise
    gain = xp.swapaxes(xp.linalg.solve(s, jac @ cov), -1, -2)         # P H^T S^-1 (N, 3, 2L)
    new = mean + (gain @ innov[..., None])[..., 0]
    new = xp.concatenate([new[:, :2], av.utility.wrap_angle(new[:, 2:], xp)], axis=-1)
    p = (xp.eye(3) - gain @ jac) @ cov
    return {"mean": new, "cov": (p + xp.swapaxes(p, -1, -2)) / 2}


class MyEKF(av.Block):
    """An extended Kalman filter for N robots, discrete with period dt.

    Ports: cmd (N, 2) in [m/s, rad/s]; measurement (N, L, 2) in [m, rad];
    estimate (N, 3) out [m, m, rad]; covariance (N, 3, 3) out.
    States: mean (N, 3) and cov (N, 3, 3), the prediction for the current
    step (at the start: mean0, cov0).

    At each step the output is the prediction corrected with this step's
    measurement; the update predicts the next step from that corrected
    estimate with this step's command.
    """

    def __init__(self, landmarks, mean0, cov0, q, r, dt=0.1):
        super().__init__()
        self.landmarks = np.asarray(landmarks, dtype=float)
        mean0 = np.asarray(mean0, dtype=float)
        self.n, self.m = len(mean0), len(self.landmarks)
        self.q, self.r, self.dt = np.asarray(q, float), np.asarray(r, float), float(dt)
        self.declare_input("cmd", (self.n, 2), unit="m/s, rad/s", feedthrough=False)
        self.declare_input("measurement", (self.n, self.m, 2), unit="m, rad")
        self.declare_discrete_state("mean", mean0)
        self.declare_discrete_state("cov", np.asarray(cov0, dtype=float))
        self.declare_output("estimate", (self.n, 3), unit="m, m, rad")
        self.declare_output("covariance", (self.n, 3, 3))
        self.declare_periodic(self.dt)

    def output(self, t, x, u, xp):
        post = ekf_correct(x["mean"], x["cov"], u["measurement"], self.landmarks, self.r, xp)
        return {"estimate": post["mean"], "covariance": post["cov"]}

    def update(self, t, x, u, xp):
        post = ekf_correct(x["mean"], x["cov"], u["measurement"], self.landmarks, self.r, xp)
        return ekf_predict(post["mean"], post["cov"], u["cmd"], self.dt, self.q, xp)
