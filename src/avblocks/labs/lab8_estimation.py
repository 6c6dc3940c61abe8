"""Lab 8's checks: localisation with an extended Kalman filter.

N unicycle robots localise themselves from range and bearing to known
landmarks. The model (the template states it): a step of ``dt`` with the
command ``(v, omega)`` held, ``x+ = x + dt (v cos th, v sin th, omega)``
(heading wrapped into (-pi, pi]) plus noise ``N(0, R(th) diag(q^2)
R(th)^T)``, ``q`` the standard deviations in the robot's frame (forward,
lateral, heading) and ``R(th)`` the rotation by the heading the step starts
from; landmark ``m`` is measured as ``(|m - p|, wrap(atan2(m_y - y, m_x - x)
- th))`` plus noise ``N(0, diag(r^2))``.

Independent truth:

* the prediction against the model's mean written here and its covariance
  ``F P F^T + R Q R^T`` with ``F`` from central finite differences of the
  motion (not the student's Jacobian);
* the correction against the posterior in information form, ``P+ = (P^-1 +
  H^T R^-1 H)^-1``, ``x+ = x + P+ H^T R^-1 (z - h(x))`` (the bearing
  innovation wrapped), ``H`` by finite differences of the measurement, on
  states where a landmark lies behind a robot (measured and predicted
  bearings on either side of +-pi);
* both return exactly symmetric covariances;
* **the exact linear-Gaussian case**: robots that turn on the spot at known
  positions (no position uncertainty, no forward or lateral noise) make the
  heading a linear Gaussian chain observed linearly through the bearings, so
  the filter must equal the Kalman filter; the grader computes the closed-
  form posterior of each step from the whole chain (the information matrix of
  the headings so far, solved at once) and compares the student's block, run
  in a diagram, step by step;
* **consistency** on the nonlinear case: the normalised estimation error
  squared ``e^T P^-1 e`` averaged over N robots driving arcs (each robot an
  independent Monte-Carlo run, noise drawn here) must lie within the
  two-sided 99 % bounds of ``chi2(3 N) / N`` (``scipy.stats.chi2``) at
  :data:`NEES_FRACTION` of the steps, and its average over the run within
  the 99 % bounds of ``chi2(3 N K) / (N K)`` widened by :data:`NEES_SLACK`.

With a seed (``--seed``, ``--student``) the poses, covariances, commands,
landmarks, noise levels and Monte-Carlo draws are drawn per student.
"""

from __future__ import annotations

import math

import numpy as np

from ..core.block import Block
from ..core.diagram import Diagram
from ..core.frontend import simulate
from ..core.sample_times import Periodic
from .grading import Failed, Lab, check_ports, compare, expect_shape

#: the control and measurement period [s]
DT = 0.1
#: the least fraction of steps whose averaged NEES lies within the per-step bounds
NEES_FRACTION = 0.85
#: the average NEES over the run may leave its 99 % bounds by this factor
#: (the steps are correlated and an EKF linearises: Bar-Shalom, Li and
#: Kirubarajan 2001, sec. 5.4)
NEES_SLACK = 0.15


def wrap(a):
    """Angles into (-pi, pi]."""
    return np.pi - np.mod(np.pi - np.asarray(a, float), 2 * np.pi)


# ------------------------------------------------------------------ the model (truth)
def motion(x, u, dt):
    """The unicycle step without noise, (N, 3), heading wrapped."""
    th = x[:, 2]
    return np.column_stack([x[:, 0] + dt * u[:, 0] * np.cos(th),
                            x[:, 1] + dt * u[:, 0] * np.sin(th), wrap(th + dt * u[:, 1])])


def rotation(th):
    """(N, 3, 3) rotations by the headings (the third axis kept)."""
    c, s = np.cos(th), np.sin(th)
    out = np.zeros((len(th), 3, 3))
    out[:, 0, 0], out[:, 0, 1], out[:, 1, 0], out[:, 1, 1] = c, -s, s, c
    out[:, 2, 2] = 1.0
    return out


def process_noise(th, q):
    """``R(th) diag(q^2) R(th)^T`` (N, 3, 3)."""
    rot = rotation(th)
    return rot @ np.diag(np.asarray(q, float) ** 2) @ np.swapaxes(rot, 1, 2)


def measure(x, landmarks):
    """(N, L, 2) range and bearing of each landmark, no noise."""
    d = landmarks[None, :, :] - x[:, None, :2]
    return np.stack([np.hypot(d[..., 0], d[..., 1]),
                     wrap(np.arctan2(d[..., 1], d[..., 0]) - x[:, None, 2])], axis=-1)


def _fd(fn, x, h=1e-6, angle_rows=()):
    """(N, M, 3) central finite differences of ``fn(x) -> (N, M)``, with the
    differences of the rows ``angle_rows`` wrapped."""
    cols = []
    for k in range(3):
        dx = np.zeros_like(x)
        dx[:, k] = h
        diff = fn(x + dx) - fn(x - dx)
        if angle_rows:
            idx = list(angle_rows)
            diff[:, idx] = wrap(diff[:, idx])
        cols.append(diff / (2 * h))
    return np.stack(cols, axis=-1)


def predict_truth(mean, cov, cmd, dt, q):
    """The prediction: the model's mean, ``F P F^T + R Q R^T`` with F by
    finite differences."""
    f = _fd(lambda y: motion(y, cmd, dt), mean, angle_rows=(2,))
    return motion(mean, cmd, dt), f @ cov @ np.swapaxes(f, 1, 2) + process_noise(mean[:, 2], q)


def correct_truth(mean, cov, z, landmarks, r, *, wrap_innovation=True, flip_bearing=False,
                  sequential=False):
    """The posterior in information form (module docstring). The keywords
    make known mistakes or variants, for the messages: the innovation not
    wrapped, the bearing's Jacobian in x and y with the wrong sign, the
    landmarks taken one at a time with the measurement relinearised at each
    updated estimate (Thrun et al. 2005, Table 7.2; not this lab's stacked
    update)."""
    n, m = len(mean), len(landmarks)
    if sequential:
        for j in range(m):
            mean, cov = correct_truth(mean, cov, z[:, j:j + 1], landmarks[j:j + 1], r,
                                      wrap_innovation=wrap_innovation,
                                      flip_bearing=flip_bearing)
        return mean, cov

    def h(y):
        return measure(y, landmarks).reshape(len(y), 2 * m)

    jac = _fd(h, mean, angle_rows=tuple(range(1, 2 * m, 2)))             # (N, 2L, 3)
    if flip_bearing:
        jac[:, 1::2, :2] *= -1
    y = (z - measure(mean, landmarks)).reshape(n, 2 * m)
    if wrap_innovation:
        y[:, 1::2] = wrap(y[:, 1::2])
    rinv = np.diag(np.tile(1.0 / np.asarray(r, float) ** 2, m))
    info = np.linalg.inv(cov) + np.swapaxes(jac, 1, 2) @ rinv @ jac
    post = np.linalg.inv(info)
    post = (post + np.swapaxes(post, 1, 2)) / 2
    step = np.einsum("nij,njk,kl,nl->ni", post, np.swapaxes(jac, 1, 2), rinv, y)
    new = mean + step
    new[:, 2] = wrap(new[:, 2])
    return new, post


# ------------------------------------------------------------------ drawn cases
def _spd(rng, n, scale):
    a = rng.normal(size=(n, 3, 3)) * np.asarray(scale)[None, :, None]
    return a @ np.swapaxes(a, 1, 2) + np.diag(np.asarray(scale) ** 2 * 0.1)


def _noise_levels(sub, k):
    rng = sub.rng(k)
    q = sub.pick((0.04, 0.01, 0.02), lambda: (round(float(rng.uniform(0.02, 0.06)), 4),
                                              round(float(rng.uniform(0.003, 0.012)), 4),
                                              round(float(rng.uniform(0.01, 0.03)), 4)))
    r = sub.pick((0.1, 0.05), lambda: (round(float(rng.uniform(0.05, 0.2)), 4),
                                       round(float(rng.uniform(0.02, 0.08)), 4)))
    return np.array(q), np.array(r)


def _landmarks(sub, k, m, radius=4.0):
    """m landmarks spread around a circle of ``radius`` [m] (jittered)."""
    rng = sub.rng(k)
    a = 2 * np.pi * (np.arange(m) + rng.uniform(-0.2, 0.2, m)) / m + rng.uniform(0, 2 * np.pi)
    rad = radius + rng.uniform(-0.3, 0.3, m)
    return np.column_stack([rad * np.cos(a), rad * np.sin(a)])


def _dict_result(value, what, n):
    if not isinstance(value, dict) or set(value) != {"mean", "cov"}:
        kind = (f"a dict with keys {sorted(value)}" if isinstance(value, dict)
                else type(value).__name__)
        raise Failed(f"{what} returned {kind}, expected a dict {{'mean': (N, 3) array, "
                     f"'cov': (N, 3, 3) array}}")
    return (expect_shape(f"mean ({what})", value["mean"], (n, 3)),
            expect_shape(f"cov ({what})", value["cov"], (n, 3, 3)))


def _call_pair(fn, what, n, *args):
    try:
        out = fn(*args, xp=np)
    except Failed as e:
        if "returned a tuple" in str(e) or "returned a list" in str(e):
            raise Failed(f"{e} (here: a dict {{'mean': (N, 3) array, 'cov': (N, 3, 3) "
                         f"array}})") from None
        raise
    return _dict_result(out, what, n)


def _symmetric(port, cov, case):
    c = np.asarray(cov, float)
    asym = np.abs(c - np.swapaxes(c, -1, -2)).max() if c.size else 0.0
    if asym != 0.0:
        raise Failed(f"port `{port}`{case}: the covariance is not symmetric (largest "
                     f"|P - P^T| = {asym:.2g}); rounding makes F P F^T and (I - K H) P "
                     f"slightly asymmetric: return (P + P^T) / 2")


def _hinted(port, want, found, atol, case, hints):
    """compare, then name a known mistake when ``found`` matches one of
    ``hints`` ({text: what that mistake computes})."""
    try:
        compare(port, want, found, atol=atol, case=case)
    except Failed as e:
        f = np.asarray(found, float)
        for text, wrong in hints.items():
            if wrong.shape == f.shape and np.allclose(f, wrong, atol=max(atol, 1e-7)):
                raise Failed(f"{e}: {text}") from None
        raise


# ------------------------------------------------------------------ checks
def _block(sub, n=3, m=4, **kw):
    rng = np.random.default_rng(0)
    mean0 = np.column_stack([rng.uniform(-2, 2, (n, 2)), rng.uniform(-3, 3, n)])
    cov0 = np.repeat((np.diag([0.1, 0.1, 0.05]) ** 2)[None], n, axis=0)
    args = dict(landmarks=_landmarks(sub, 0, m), mean0=mean0, cov0=cov0,
                q=(0.04, 0.01, 0.02), r=(0.1, 0.05), dt=DT)
    args.update(kw)
    return sub.MyEKF(**args)


def check_ports_(sub):
    b = _block(sub)
    check_ports(b, inputs={"cmd": (3, 2), "measurement": (3, 4, 2)},
                outputs={"estimate": (3, 3), "covariance": (3, 3, 3)})
    st = b.sample_time
    if not (isinstance(st, Periodic) and abs(st.period - DT) < 1e-12):
        raise Failed(f"MyEKF must be discrete with the period dt = {DT:g} s "
                     f"(self.declare_periodic(dt), as in the template); found {st}")
    return "declared as in the template: discrete, period dt"


def check_predict(sub):
    rng = sub.rng(1)
    n = 6
    dt = sub.pick(DT, lambda: round(float(rng.uniform(0.05, 0.2)), 3))
    q, _ = _noise_levels(sub, 2)
    mean = np.column_stack([rng.uniform(-3, 3, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    mean[0, 2] = np.pi - 0.01                         # turns across +-pi
    cmd = np.column_stack([rng.uniform(0.2, 1.5, n), rng.uniform(-2, 2, n)])
    cmd[0, 1] = 1.0
    cov = _spd(rng, n, (0.2, 0.2, 0.1))
    case = f" (dt = {dt:g} s, q = {tuple(float(v) for v in q)})"
    m_found, p_found = _call_pair(sub.ekf_predict, "ekf_predict", n, mean.copy(), cov.copy(),
                                  cmd.copy(), dt, q.copy())
    m_want, p_want = predict_truth(mean, cov, cmd, dt, q)
    unwrapped = m_want.copy()
    unwrapped[:, 2] = mean[:, 2] + dt * cmd[:, 1]
    _hinted("mean (ekf_predict)", m_want, m_found, 1e-12, case,
            {"the heading was not wrapped into (-pi, pi] (av.utility.wrap_angle)": unwrapped})
    f_true = _fd(lambda y: motion(y, cmd, dt), mean, angle_rows=(2,))
    noise = process_noise(mean[:, 2], q)
    flips = {}
    for rows, what in (((0,), "d x / d theta = -v dt sin theta"),
                       ((1,), "d y / d theta = v dt cos theta"),
                       ((0, 1), "d x / d theta = -v dt sin theta, d y / d theta = v dt cos "
                                "theta")):
        f_flip = f_true.copy()
        f_flip[:, list(rows), 2] *= -1
        flips[f"a sign in the Jacobian F is wrong ({what})"] = \
            f_flip @ cov @ np.swapaxes(f_flip, 1, 2) + noise
    body = np.repeat(np.diag(q ** 2)[None], n, axis=0)
    fpf = f_true @ cov @ np.swapaxes(f_true, 1, 2)
    _hinted("cov (ekf_predict)", p_want, p_found, 1e-9, case + ": F P F^T + R Q R^T", {
        **flips,
        "the process noise was added in the robot's frame: rotate it into the world, "
        "R(theta) diag(q^2) R(theta)^T": fpf + body,
        "the process noise was rotated by the heading after the step; rotate by the "
        "heading the step starts from": fpf + process_noise(m_want[:, 2], q),
        "the covariance was not propagated through F: F P F^T": cov + process_noise(
            mean[:, 2], q),
        "q holds standard deviations: the noise covariance is diag(q^2)":
            fpf + process_noise(mean[:, 2], np.sqrt(q))})
    _symmetric("cov (ekf_predict)", p_found, case)
    return f"the unicycle step, F P F^T and the body-frame noise rotated, for {n} robots"


def _behind(rng, n, landmarks):
    """Means, covariances and measurements for the correction, robot 0 with
    landmark 0 straight behind it (bearings on either side of +-pi)."""
    mean = np.column_stack([rng.uniform(-2, 2, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    d = landmarks[0] - mean[0, :2]
    mean[0, 2] = np.arctan2(d[1], d[0]) + np.pi - 0.004     # the landmark at bearing -pi + 0.004
    cov = _spd(rng, n, (0.15, 0.15, 0.05))
    truth = mean + rng.multivariate_normal(np.zeros(3), np.diag([0.05, 0.05, 0.01]) ** 2, n)
    truth[0] = mean[0]
    truth[0, 2] += 0.012              # robot 0 turned a little further: measured near +pi
    return mean, cov, truth


def check_correct(sub):
    rng = sub.rng(3)
    n = 5
    m = sub.pick(3, lambda: int(rng.integers(2, 6)))
    lm = _landmarks(sub, 4, m)
    _, r = _noise_levels(sub, 2)
    mean, cov, truth = _behind(rng, n, lm)
    z = measure(truth, lm) + rng.normal(size=(n, m, 2)) * r * 0.3
    z[0, 0, 1] = wrap(measure(truth, lm)[0, 0, 1])     # exactly as measured: across +-pi
    z[..., 1] = wrap(z[..., 1])
    case = f" ({m} landmarks, r = {tuple(float(v) for v in r)}; robot 0 has landmark 0 behind it)"
    m_found, p_found = _call_pair(sub.ekf_correct, "ekf_correct", n, mean.copy(), cov.copy(),
                                  z.copy(), lm.copy(), r.copy())
    m_want, p_want = correct_truth(mean, cov, z, lm, r)
    m_raw, _ = correct_truth(mean, cov, z, lm, r, wrap_innovation=False)
    m_flip, p_flip = correct_truth(mean, cov, z, lm, r, flip_bearing=True)
    m_seq, p_seq = correct_truth(mean, cov, z, lm, r, sequential=True)
    seq = ("the landmarks were taken one at a time, the measurement relinearised at each "
           "updated estimate (a valid EKF, Thrun et al. Table 7.2, but not this lab's): stack "
           "the 2 L measurements into one update at the prediction, as the template says")
    flipped = ("the sign of the bearing's Jacobian in x and y is wrong (d beta / d x = "
               "(m_y - y) / q, d beta / d y = -(m_x - x) / q, q = |m - p|^2)")
    _hinted("mean (ekf_correct)", m_want, m_found, 1e-8, case, {
        "the bearing innovation z - h(x) was not wrapped into (-pi, pi]: a landmark behind "
        "the robot is measured near pi and predicted near -pi": m_raw,
        "the mean was not corrected": mean, flipped: m_flip, seq: m_seq})
    _hinted("cov (ekf_correct)", p_want, p_found, 1e-9, case, {
        "the covariance was not updated: P+ = (I - K H) P": cov, flipped: p_flip,
        seq: p_seq})
    _symmetric("cov (ekf_correct)", p_found, case)
    return f"the posterior of range and bearing to {m} landmarks, one behind a robot"


class Playback(Block):
    """Recorded signals played back: output ``name`` is row ``k = round(t /
    dt)`` of the array given as ``name`` (the last row after the end). The
    checks feed the student's filter the commands and measurements they
    recorded this way.

    Ports
    -----
    one output per keyword, of the array's shape without its first axis

    Parameters
    ----------
    dt : float
        The period [s] (discrete block).
    **series : array_like
        ``name=(K + 1, ...)`` arrays, one row per step.
    """

    def __init__(self, dt, **series):
        super().__init__()
        self.dt = float(dt)
        self.series = {k: np.asarray(v, float) for k, v in series.items()}
        for k, v in self.series.items():
            self.declare_output(k, v.shape[1:])
        self.declare_periodic(dt)

    def output(self, t, x, u, xp):
        out = {}
        for k, v in self.series.items():
            out[k] = v[min(int(round(t / self.dt)), len(v) - 1)]
        return out


def _run(sub, block, cmd, z, steps, dt):
    d = Diagram()
    src = d.add(Playback(dt, cmd=cmd, measurement=z), name="truth")
    ekf = d.add(block, name="ekf")
    d.connect(src.cmd, ekf.cmd)
    d.connect(src.measurement, ekf.measurement)
    res = simulate(d, steps * dt, dt=dt, log=[ekf.estimate, ekf.covariance])
    est = np.asarray(res[ekf.estimate])
    cov = np.asarray(res[ekf.covariance])
    if len(est) != steps + 1:
        raise Failed(f"the run logged {len(est)} steps, expected {steps + 1}")
    return est, cov


def heading_chain_posterior(mu0, var0, turns, q_th, bearings, sigma_b):
    """The Kalman filter's answer for a heading alone, in closed form: the
    posterior of ``theta_k`` given the bearings up to step k, for every k,
    from the whole chain ``theta_{k+1} = theta_k + turns_k + w_k`` (``w_k ~
    N(0, q_th^2)``, ``theta_0 ~ N(mu0, var0)``) observed as ``y_{k,l} =
    theta_k + v`` (``v ~ N(0, sigma_b^2)``; ``bearings`` (K+1, L) holds the
    ``y``): the information matrix of ``theta_0..theta_k`` (tridiagonal)
    solved at once, its last row. Returns ``(means (K+1,), variances (K+1,))``."""
    steps = len(bearings)
    means, variances = np.zeros(steps), np.zeros(steps)
    for k in range(steps):
        n = k + 1
        info = np.zeros((n, n))
        vec = np.zeros(n)
        info[0, 0] += 1.0 / var0
        vec[0] += mu0 / var0
        for j in range(k):                          # theta_{j+1} - theta_j = turns_j + w
            a = np.zeros(n)
            a[j], a[j + 1] = -1.0, 1.0
            info += np.outer(a, a) / q_th ** 2
            vec += a * turns[j] / q_th ** 2
        for j in range(n):
            info[j, j] += len(bearings[j]) / sigma_b ** 2
            vec[j] += np.sum(bearings[j]) / sigma_b ** 2
        cov = np.linalg.inv(info)
        sol = cov @ vec
        means[k], variances[k] = sol[-1], cov[-1, -1]
    return means, variances


def _linear_hint(found, mu, mu0, var0, turns, q_th, y, sigma_b, err):
    """What a wrong run of the linear case looks like (a known mistake)."""
    steps = len(mu)
    prior = np.concatenate([[mu0], mu[:-1] + turns])           # the filter's predictions
    if np.all(np.abs(wrap(found - prior)) < 1e-8):
        return ("the estimate is the prediction: the output must be corrected with this "
                "step's measurement")
    # the state never keeps a correction: predictions from mu0 alone, each corrected once
    m_k = mu0 + np.concatenate([[0.0], np.cumsum(turns)])
    v_k = var0 + q_th ** 2 * np.arange(steps)
    info = 1 / v_k + y.shape[1] / sigma_b ** 2
    lost = (m_k / v_k + y.sum(axis=1) / sigma_b ** 2) / info
    if np.all(np.abs(wrap(found - lost)) < 1e-8):
        return ("the corrections are lost: the update must predict from the corrected "
                "estimate (correct with the measurement, then predict), not from the state's "
                "prediction")
    if np.any(np.abs(np.abs(err) - 2 * np.pi) < 0.5) or np.max(np.abs(err)) > 1.0:
        return ("the estimate jumped by about 2 pi or went astray: wrap the bearing "
                "innovation into (-pi, pi]")
    return ""


def check_linear(sub):
    rng = sub.rng(5)
    n, steps = 4, 40
    m = sub.pick(3, lambda: int(rng.integers(2, 5)))
    lm = _landmarks(sub, 6, m)
    q_th, sigma_b = sub.pick((0.03, 0.05), lambda: (round(float(rng.uniform(0.01, 0.05)), 4),
                                                     round(float(rng.uniform(0.02, 0.08)), 4)))
    sigma_r = 0.1
    pos = rng.uniform(-2, 2, (n, 2))
    var0 = 0.2 ** 2
    th0 = rng.uniform(-np.pi, np.pi, n)
    mu0 = th0 + rng.normal(scale=0.2, size=n)
    omega = rng.uniform(1.0, 2.5, (steps + 1, n)) * rng.choice([-1, 1], n)   # spin past +-pi
    cmd = np.stack([np.zeros((steps + 1, n)), omega], axis=-1)
    th = np.zeros((steps + 1, n))
    th[0] = th0
    for k in range(steps):
        th[k + 1] = th[k] + DT * omega[k] + rng.normal(scale=q_th, size=n)
    true = np.stack([np.broadcast_to(pos[:, 0], (steps + 1, n)),
                     np.broadcast_to(pos[:, 1], (steps + 1, n)), th], axis=-1)
    z = np.stack([measure(true[k], lm) for k in range(steps + 1)])
    z = z + rng.normal(size=z.shape) * np.array([sigma_r, sigma_b])
    z[..., 1] = wrap(z[..., 1])
    mean0 = np.column_stack([pos, wrap(mu0)])
    cov0 = np.zeros((n, 3, 3))
    cov0[:, 2, 2] = var0
    block = sub.MyEKF(landmarks=lm, mean0=mean0, cov0=cov0, q=(0.0, 0.0, q_th),
                      r=(sigma_r, sigma_b), dt=DT)
    est, cov = _run(sub, block, cmd, z, steps, DT)
    case = (f" (robots spinning on the spot at known positions, {m} landmarks, "
            f"q = (0, 0, {q_th:g}), bearing std {sigma_b:g})")
    for i in range(n):
        beta = np.arctan2(lm[None, :, 1] - pos[i, 1], lm[None, :, 0] - pos[i, 0])
        y = beta - z[:, i, :, 1]                              # theta_k + noise, mod 2 pi
        y = th[:, i, None] + wrap(y - th[:, i, None])         # unwrapped along the chain
        turns = DT * omega[:-1, i]
        mu, var = heading_chain_posterior(mu0[i], var0, turns, q_th, y, sigma_b)
        err = wrap(est[:, i, 2] - mu)
        k = int(np.argmax(np.abs(err)))
        if abs(err[k]) > 1e-8:
            hint = _linear_hint(est[:, i, 2], mu, mu0[i], var0, turns, q_th, y, sigma_b, err)
            raise Failed(f"port `estimate` (heading){case}, robot {i}: at step {k} expected "
                         f"{wrap(mu[k]):.6f} (the Kalman filter, in closed form), found "
                         f"{est[k, i, 2]:.6f}" + (f": {hint}" if hint else ""))
        compare("covariance (heading variance)", var, cov[:, i, 2, 2], atol=1e-12,
                rtol=1e-8, case=f"{case}, robot {i}, steps 0 to {steps}")
    compare("estimate (position)", np.broadcast_to(pos, (steps + 1, n, 2)), est[..., :2],
            atol=1e-9, case=f"{case}: the positions are known and must not move")
    return (f"the Kalman filter's posterior in closed form at each of {steps + 1} steps, "
            f"{n} robots turning past +-pi")


def _nees_run(sub, n, steps, lm, q, r, rng):
    """A Monte-Carlo run of n robots driving arcs (circles of 0.8 to 1.5 m
    with a varying turn rate, so that they stay well inside the landmarks:
    an EKF linearises, and close to a landmark its bearing is far from
    linear): true states, commands, measurements, the initial estimate and
    covariance."""
    p0 = np.diag([0.1, 0.1, 0.05]) ** 2
    x = np.column_stack([rng.uniform(-1.0, 1.0, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    t = np.arange(steps + 1) * DT
    speed = rng.uniform(0.3, 0.6, n)
    v = np.broadcast_to(speed, (steps + 1, n))
    w = (speed / rng.uniform(0.8, 1.5, n) * rng.choice([-1.0, 1.0], n)
         + 0.2 * np.sin(t[:, None] * rng.uniform(0.5, 1.5, n) + rng.uniform(0, 6, n)))
    cmd = np.stack([v, w], axis=-1)
    true = np.zeros((steps + 1, n, 3))
    true[0] = x
    for k in range(steps):
        noise = np.einsum("nij,nj->ni", rotation(true[k, :, 2]),
                          rng.normal(size=(n, 3)) * q)
        nxt = motion(true[k], cmd[k], DT) + noise
        nxt[:, 2] = wrap(nxt[:, 2])
        true[k + 1] = nxt
    z = np.stack([measure(true[k], lm) for k in range(steps + 1)])
    z = z + rng.normal(size=z.shape) * r
    z[..., 1] = wrap(z[..., 1])
    mean0 = x + rng.multivariate_normal(np.zeros(3), p0, n)
    mean0[:, 2] = wrap(mean0[:, 2])
    return true, cmd, z, mean0, np.repeat(p0[None], n, axis=0)


def nees_bounds(dof_each, count, level=0.99):
    """The two-sided ``level`` interval of the average of ``count``
    independent NEES values of ``dof_each`` degrees of freedom:
    ``chi2(dof_each count).ppf((1 -+ level) / 2) / count``."""
    from scipy.stats import chi2
    a = (1 - level) / 2
    return (float(chi2.ppf(a, dof_each * count)) / count,
            float(chi2.ppf(1 - a, dof_each * count)) / count)


def check_nees(sub):
    rng = sub.rng(7)
    n, steps = 50, 100
    m = sub.pick(4, lambda: int(rng.integers(3, 6)))
    lm = _landmarks(sub, 8, m, radius=5.0)
    q, r = _noise_levels(sub, 9)
    true, cmd, z, mean0, cov0 = _nees_run(sub, n, steps, lm, q, r, rng)
    block = sub.MyEKF(landmarks=lm, mean0=mean0, cov0=cov0, q=tuple(q), r=tuple(r), dt=DT)
    est, cov = _run(sub, block, cmd, z, steps, DT)
    err = true - est
    err[..., 2] = wrap(err[..., 2])
    try:
        nees = np.einsum("kni,kni->kn", err, np.linalg.solve(cov, err[..., None])[..., 0])
    except np.linalg.LinAlgError:
        raise Failed("port `covariance`: a covariance became singular during the run "
                     "(not positive definite)") from None
    if not np.all(np.isfinite(nees)):
        raise Failed("port `covariance`: NaN or inf in the estimation error's NEES")
    avg = nees.mean(axis=1)                                   # (K+1,) averaged over robots
    lo, hi = nees_bounds(3, n)
    inside = float(np.mean((avg >= lo) & (avg <= hi)))
    alo, ahi = nees_bounds(3, n * (steps + 1))
    overall = float(avg.mean())
    what = (f"the NEES e^T P^-1 e of {n} robots driving arcs for {steps} steps, {m} "
            f"landmarks, q = {tuple(float(v) for v in q)}, r = {tuple(float(v) for v in r)}")
    if inside < NEES_FRACTION or not (alo * (1 - NEES_SLACK) <= overall
                                      <= ahi * (1 + NEES_SLACK)):
        side = ("too large: the covariance is smaller than the errors (overconfident: noise "
                "missing, or the Jacobians wrong)" if overall > 3 else
                "too small: the covariance is larger than the errors (not reduced by the "
                "measurements?)")
        raise Failed(f"{what}: averaged over the robots it lies within the 99 % bounds "
                     f"[{lo:.2f}, {hi:.2f}] of chi2(3 N) / N at {inside:.0%} of the steps "
                     f"(expected at least {NEES_FRACTION:.0%}), on average {overall:.2f} "
                     f"(expected within [{alo * (1 - NEES_SLACK):.2f}, "
                     f"{ahi * (1 + NEES_SLACK):.2f}], 3 for a consistent filter): {side}")
    rmse = math.sqrt(float(np.mean(err[..., :2] ** 2)) * 2)
    return (f"consistent: average NEES {overall:.2f} (3 expected), within the per-step 99 % "
            f"bounds at {inside:.0%} of the steps; position error {rmse:.3f} m RMS")


LAB = Lab(8, "estimation", "Localisation with an extended Kalman filter: the exact "
          "linear-Gaussian case and consistency (NEES)",
          names=("ekf_predict", "ekf_correct", "MyEKF"),
          checks=[("ports", check_ports_),
                  ("prediction: the unicycle model and body-frame noise", check_predict),
                  ("correction: range and bearing to landmarks", check_correct),
                  ("the linear-Gaussian case: the Kalman filter in closed form", check_linear),
                  ("consistency: NEES within the chi-square bounds", check_nees)])
