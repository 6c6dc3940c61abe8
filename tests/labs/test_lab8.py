"""Lab 8 (estimation) beyond the shared lab tests: the check's truths
against second, independent computations (analytic Jacobians against the
finite differences, the EKF's gain form against the information form, the
heading chain's closed form against a scalar Kalman filter run step by
step, the chi-square bounds against their definition), the playback block's
timing, and the consistency check catching what an inconsistent filter
does (not only the pointwise checks before it)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from avblocks.core.diagram import Diagram
from avblocks.core.frontend import simulate
from avblocks.labs import Lab, get, run_checks
from avblocks.labs import lab8_estimation as lab8

from .mutations import write

HERE = Path(__file__).resolve().parent


def _state(rng, n):
    mean = np.column_stack([rng.uniform(-2, 2, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    a = rng.normal(size=(n, 3, 3)) * 0.2
    return mean, a @ np.swapaxes(a, 1, 2) + 0.01 * np.eye(3)


def test_the_finite_difference_jacobians_are_the_analytic_ones():
    rng = np.random.default_rng(0)
    mean, _ = _state(rng, 7)
    cmd = np.column_stack([rng.uniform(0, 2, 7), rng.uniform(-2, 2, 7)])
    dt = 0.1
    f = lab8._fd(lambda y: lab8.motion(y, cmd, dt), mean, angle_rows=(2,))
    th, v = mean[:, 2], cmd[:, 0]
    want = np.repeat(np.eye(3)[None], 7, axis=0)
    want[:, 0, 2], want[:, 1, 2] = -dt * v * np.sin(th), dt * v * np.cos(th)
    np.testing.assert_allclose(f, want, atol=1e-9)
    lm = rng.uniform(-5, 5, (4, 2))
    h = lab8._fd(lambda y: lab8.measure(y, lm).reshape(7, 8), mean,
                 angle_rows=(1, 3, 5, 7))
    d = lm[None] - mean[:, None, :2]
    q = np.sum(d * d, axis=-1)
    want_h = np.zeros((7, 4, 2, 3))
    want_h[:, :, 0, 0], want_h[:, :, 0, 1] = -d[..., 0] / np.sqrt(q), -d[..., 1] / np.sqrt(q)
    want_h[:, :, 1, 0], want_h[:, :, 1, 1] = d[..., 1] / q, -d[..., 0] / q
    want_h[:, :, 1, 2] = -1.0
    np.testing.assert_allclose(h, want_h.reshape(7, 8, 3), atol=1e-8)


def test_the_information_form_is_the_ekf_gain_form():
    """correct_truth (information form, finite-difference H) against the
    textbook gain form K = P H^T (H P H^T + R)^-1 written here with the
    analytic H and a loop over robots (Thrun et al. 2005, Table 7.2)."""
    rng = np.random.default_rng(1)
    n, m = 5, 3
    mean, cov = _state(rng, n)
    lm = rng.uniform(-5, 5, (m, 2))
    r = np.array([0.1, 0.05])
    z = lab8.measure(mean + rng.normal(scale=0.05, size=(n, 3)), lm)
    got_m, got_p = lab8.correct_truth(mean, cov, z, lm, r)
    for i in range(n):
        rows, inno = [], []
        for j in range(m):
            dx, dy = lm[j] - mean[i, :2]
            q = dx * dx + dy * dy
            rows += [[-dx / np.sqrt(q), -dy / np.sqrt(q), 0.0], [dy / q, -dx / q, -1.0]]
            bearing = np.arctan2(dy, dx) - mean[i, 2]
            inno += [z[i, j, 0] - np.sqrt(q),
                     (z[i, j, 1] - bearing + np.pi) % (2 * np.pi) - np.pi]
        h = np.array(rows)
        s = h @ cov[i] @ h.T + np.diag(np.tile(r ** 2, m))
        k = cov[i] @ h.T @ np.linalg.inv(s)
        post = mean[i] + k @ np.array(inno)
        np.testing.assert_allclose(got_m[i, :2], post[:2], atol=1e-8)
        assert abs(lab8.wrap(got_m[i, 2] - post[2])) < 1e-8
        np.testing.assert_allclose(got_p[i], (np.eye(3) - k @ h) @ cov[i], atol=1e-9)


def test_the_heading_chain_closed_form_is_the_scalar_kalman_filter():
    rng = np.random.default_rng(2)
    steps, q, sb = 30, 0.04, 0.06
    turns = rng.uniform(-0.2, 0.2, steps)
    y = rng.normal(size=(steps + 1, 2))
    mu, var = lab8.heading_chain_posterior(0.3, 0.25, turns, q, y, sb)
    m, v = 0.3, 0.25
    for k in range(steps + 1):
        for obs in y[k]:                       # one measurement at a time
            g = v / (v + sb ** 2)
            m, v = m + g * (obs - m), (1 - g) * v
        assert abs(m - mu[k]) < 1e-12 and abs(v - var[k]) < 1e-14
        if k < steps:
            m, v = m + turns[k], v + q ** 2


def test_the_nees_bounds_are_the_chi_square_quantiles():
    from scipy.stats import chi2
    lo, hi = lab8.nees_bounds(3, 50)
    assert (lo, hi) == pytest.approx((chi2.ppf(0.005, 150) / 50, chi2.ppf(0.995, 150) / 50))
    # the mean of chi2(k) / k is 1: 3 NEES degrees of freedom centre on 3
    assert lo < 3 < hi and hi - 3 > 3 - lo


def test_the_playback_block_plays_row_k_at_step_k():
    seq = np.arange(12.0).reshape(6, 2)
    d = Diagram()
    src = d.add(lab8.Playback(0.1, a=seq), name="src")
    res = simulate(d, 0.5, dt=0.1, log=[src.a])
    np.testing.assert_array_equal(np.asarray(res[src.a]), seq)


@pytest.mark.parametrize("kind,says", [
    ("no_update", "too small: the covariance is larger than the errors"),
    ("body_frame", "too large: the covariance is smaller than the errors"),
    ("jacobian_h", "too large"),
    ("unwrapped", "too large"),
])
def test_the_consistency_check_catches_an_inconsistent_filter(tmp_path, kind, says):
    lab = get(8)
    only = Lab(8, lab.name, lab.title, names=lab.names,
               checks=[c for c in lab.checks if c[0].startswith("consistency")])
    r = run_checks(only, write(tmp_path, 8, kind))
    assert not r.passed and says in r.checks[0].message, r.checks[0].message
    assert "99 % bounds" in r.checks[0].message


JOSEPH = ("    p = (xp.eye(3) - gain @ jac) @ cov\n",
          "    a = xp.eye(3) - gain @ jac\n"
          "    p = a @ cov @ xp.swapaxes(a, -1, -2) + gain @ noise @ xp.swapaxes(gain, -1, -2)\n")
SEQUENTIAL = (
    "def ekf_correct(mean, cov, z, landmarks, r, xp=np):\n",
    "def ekf_correct(mean, cov, z, landmarks, r, xp=np):\n"
    "    if z.shape[1] > 1:                # one landmark at a time, relinearised\n"
    "        for j in range(z.shape[1]):\n"
    "            post = ekf_correct(mean, cov, z[:, j:j + 1], landmarks[j:j + 1], r, xp)\n"
    "            mean, cov = post['mean'], post['cov']\n"
    "        return post\n")


def _variant(tmp_path, name, find, replace):
    text = (HERE / "solutions" / "lab8_estimation.py").read_text()
    assert text.count(find) == 1
    f = tmp_path / name
    f.write_text(text.replace(find, replace))
    return f


def test_the_joseph_form_passes_every_check(tmp_path):
    """The Joseph form of the covariance update (a different, stabler
    formula for the same posterior) passes, fixed cases and drawn ones."""
    f = _variant(tmp_path, "joseph.py", *JOSEPH)
    for seed in (None, 3):
        r = run_checks(get(8), f, seed=seed)
        assert r.passed, r.text()


def test_landmarks_one_at_a_time_are_named_as_such(tmp_path):
    f = _variant(tmp_path, "sequential.py", *SEQUENTIAL)
    lab = get(8)
    only = Lab(8, lab.name, lab.title, names=lab.names,
               checks=[c for c in lab.checks if c[0].startswith("correction")])
    r = run_checks(only, f)
    assert not r.passed and "the landmarks were taken one at a time" in r.checks[0].message
