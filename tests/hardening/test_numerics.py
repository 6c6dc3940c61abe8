"""Numerical edge cases checked against libraries nobody here wrote:
quadprog and cvxopt for the safety filter's QP."""

import os

import numpy as np
import pytest

from avblocks.controllers.collision_avoidance import min_norm_qp

quadprog = pytest.importorskip("quadprog") if not __import__("os").environ.get("CI") \
    else __import__("quadprog")
cvxopt = pytest.importorskip("cvxopt") if not __import__("os").environ.get("CI") \
    else __import__("cvxopt")


def qp_quadprog(u0, a, b):
    """argmin |u - u0|^2 s.t. a u <= b with quadprog (C^T x >= b form)."""
    d = len(u0)
    x, *_ = quadprog.solve_qp(np.eye(d), np.asarray(u0, float), -a.T.astype(float),
                              -np.asarray(b, float), 0)
    return x


def qp_cvxopt(u0, a, b):
    from cvxopt import matrix, solvers
    solvers.options["show_progress"] = False
    solvers.options["abstol"] = 1e-12
    solvers.options["reltol"] = 1e-12
    solvers.options["feastol"] = 1e-12
    d = len(u0)
    sol = solvers.qp(matrix(np.eye(d)), matrix(-np.asarray(u0, float)),
                     matrix(a.astype(float)), matrix(np.asarray(b, float)))
    return np.array(sol["x"]).ravel()


def ours(u0, a, b):
    return min_norm_qp(np.asarray(u0, float)[None], a[None].astype(float),
                       np.asarray(b, float)[None], np.ones((1, len(b)), bool))[0]


def test_nearly_antiparallel_constraints_issue_example():
    a = np.array([[-1.0, 1.0], [1.0, -1.00003]])
    b = np.array([1e-7, 1e-7])
    u0 = np.array([-1.7, 0.1])
    x = ours(u0, a, b)
    xq, xc = qp_quadprog(u0, a, b), qp_cvxopt(u0, a, b)
    np.testing.assert_allclose(xq, xc, atol=1e-6)        # the two references agree
    np.testing.assert_allclose(x, xq, rtol=1e-7, atol=1e-12)
    assert np.all(a @ x - b <= 1e-15)
    np.testing.assert_allclose(x, [-0.0066667666, -0.0066666666], rtol=1e-6)


@pytest.mark.parametrize("eps", [1e-2, 1e-4, 1e-6, 1e-8])
def test_thin_wedges_against_quadprog(eps):
    rng = np.random.default_rng(1)
    for _ in range(50):
        n = rng.normal(size=2)
        n /= np.linalg.norm(n)
        rot = np.array([[np.cos(eps), -np.sin(eps)], [np.sin(eps), np.cos(eps)]])
        a = np.stack([n, -(rot @ n)]) * rng.uniform(0.5, 3.0, (2, 1))
        b = rng.uniform(0, 1e-3, 2)                      # u = 0 feasible (CBF case)
        u0 = rng.normal(size=2) * 2
        x, xq = ours(u0, a, b), qp_quadprog(u0, a, b)
        assert np.all(a @ x - b <= 1e-9 * (1 + np.abs(b)))
        # same optimal cost; the point itself to the wedge's conditioning
        assert np.sum((x - u0) ** 2) == pytest.approx(np.sum((xq - u0) ** 2),
                                                      rel=1e-7, abs=1e-12)
        np.testing.assert_allclose(x, xq, atol=1e-9 / eps)


@pytest.mark.parametrize("dim", [2, 3])
def test_random_qps_against_quadprog_and_cvxopt(dim):
    rng = np.random.default_rng(7 + dim)
    for trial in range(120):
        k = rng.integers(1, 5)
        a = rng.normal(size=(k, dim))
        b = rng.uniform(0, 2, k)
        u0 = rng.normal(size=dim) * 3
        x, xq = ours(u0, a, b), qp_quadprog(u0, a, b)
        np.testing.assert_allclose(x, xq, atol=1e-8, err_msg=f"trial {trial}")
        if trial % 10 == 0:
            np.testing.assert_allclose(x, qp_cvxopt(u0, a, b), atol=1e-6)


# rotor positions (unit arm, body x forward, y left) and spin (+1: counter-
# clockwise seen from above) typed from the airframes' own documentation
_AIRFRAMES = {
    "x": ([(1, 1), (-1, 1), (-1, -1), (1, -1)], [+1, -1, +1, -1]),
    "crazyflie": ([(1, -1), (-1, -1), (-1, 1), (1, 1)], [+1, -1, +1, -1]),
    "px4": ([(1, -1), (-1, 1), (1, 1), (-1, -1)], [+1, +1, -1, -1]),
}


@pytest.mark.parametrize("frame", sorted(_AIRFRAMES))
def test_named_airframes_match_their_motor_layout(frame):
    from avblocks.vehicles.quadrotor import rotors_to_wrench, wrench_to_rotors
    pos, ccw = _AIRFRAMES[frame]
    pos = np.array(pos, float) / np.sqrt(2)
    arm, km = 0.046, 0.006
    f = np.random.default_rng(3).uniform(0, 1, (5, 4))
    # truth: r x F for each rotor, plus the drag reaction -ccw * km * f about z
    tau = np.zeros((5, 3))
    for i in range(4):
        r = np.array([*(arm * pos[i]), 0.0])
        F = np.zeros((5, 3))
        F[:, 2] = f[:, i]
        tau += np.cross(r, F)
        tau[:, 2] -= ccw[i] * km * f[:, i]
    w = rotors_to_wrench(f, arm, km, frame)
    np.testing.assert_allclose(w[:, 0], f.sum(1), atol=1e-12)
    np.testing.assert_allclose(w[:, 1:], tau, atol=1e-12)
    np.testing.assert_allclose(wrench_to_rotors(w, arm, km, frame), f, atol=1e-12)


def _step_diagram(te=0.33):
    """x' = s(t) - x^3, x(0) = 0.5, s a Step from 0.2 to 1.5 at te."""
    import avblocks as av
    d = av.Diagram()
    s = d.add(av.blocks.Step(time=te, before=[0.2], after=[1.5]), name="s")
    x = d.add(av.blocks.Integrator(np.array([0.5])), name="x")
    f = d.add(av.blocks.Function(lambda t, u, xs: u - xs ** 3,
                                 inputs={"u": (1,), "xs": (1,)}, outputs={"y": (1,)}),
              name="f")
    d.connect(s.y, f.u)
    d.connect(x.y, f.xs)
    d.connect(f.y, x.u)
    return d


def _step_error(dt, te=0.33, t_final=1.0, backend="numpy"):
    """|x(1) - truth| for the diagram of :func:`_step_diagram`."""
    from scipy.integrate import solve_ivp

    import avblocks as av
    res = av.simulate(_step_diagram(te), t_final, dt=dt, log=["x.y"], backend=backend)
    # truth: two tight solves joined at te
    a = solve_ivp(lambda t, y: 0.2 - y ** 3, (0, te), [0.5], rtol=1e-13, atol=1e-14)
    b = solve_ivp(lambda t, y: 1.5 - y ** 3, (te, t_final), a.y[:, -1], rtol=1e-13,
                  atol=1e-14)
    return abs(float(res["x.y"][-1].ravel()[0]) - b.y[0, -1])


def test_step_under_rk4_keeps_fourth_order():
    errs = [_step_error(dt) for dt in (0.1, 0.05, 0.025)]
    ratios = [errs[i] / errs[i + 1] for i in range(2)]
    # 2^4 = 16 per halving (first order, the straddled switch, would give ~2)
    assert all(12 < r < 20 for r in ratios), (errs, ratios)
    assert errs[-1] < 1e-7


@pytest.mark.jax
def test_step_under_rk4_keeps_fourth_order_on_the_compiled_backend():
    """The compiled backend splits the major step at a Step's switch as the
    NumPy simulator does: same fourth order, same values to round-off."""
    if os.environ.get("CI"):
        import jax  # noqa: F401 - in CI the jax extra is installed: never skip
    else:
        pytest.importorskip("jax")
    errs = [_step_error(dt, backend="jax") for dt in (0.1, 0.05, 0.025)]
    ratios = [errs[i] / errs[i + 1] for i in range(2)]
    assert all(12 < r < 20 for r in ratios), (errs, ratios)
    assert errs[-1] < 1e-7
    for dt in (0.1, 0.025):
        assert abs(_step_error(dt, backend="jax") - _step_error(dt)) < 1e-12


@pytest.mark.jax
def test_compiled_gradient_with_respect_to_a_switch_time():
    """The split integrates up to the switch exactly, so d x(1) / d time
    (reverse mode) equals central differences on the NumPy engine."""
    if os.environ.get("CI"):
        import jax  # noqa: F401 - in CI the jax extra is installed: never skip
    else:
        pytest.importorskip("jax")
    import avblocks as av
    d = _step_diagram(0.33)
    g = av.grad(lambda res: res["x.y"][-1].sum(), d, ["s.time"], 1.0, dt=0.05, log=["x.y"])

    def end(te):
        return float(av.simulate(d, 1.0, dt=0.05, log=["x.y"],
                                 params={"s.time": te})["x.y"][-1].sum())
    h = 1e-6
    fd = (end(0.33 + h) - end(0.33 - h)) / (2 * h)
    assert abs(float(g["s.time"]) - fd) <= 1e-5 * abs(fd)
    # per-run switch times in one ensemble equal single NumPy runs
    times = np.array([0.12, 0.33, 0.5, 0.71])
    ens = av.compile(d, 1.0, dt=0.05, log=["x.y"]).ensemble(params={"s.time": times})
    for i, te in enumerate(times):
        one = av.simulate(d, 1.0, dt=0.05, log=["x.y"], params={"s.time": te})
        assert np.abs(ens["x.y"][i] - one["x.y"]).max() < 1e-12
