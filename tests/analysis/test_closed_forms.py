"""The examples of docs/linear-analysis.md against their closed forms.

* The paper's leader-follower formation (eqs. 2-5) behind a leader driving
  straight at v0: every follower contributes the poles -K_l, -K_alpha
  (the feedback linearisation's error dynamics) and -v0/d (its heading's
  internal dynamics, derived in the docs page), the leader three zeros.
  Tolerance 1e-9 (round-off of a 12 x 12 eigenproblem).
* Consensus on a ring: A = -K (L kron I_2) and the slowest nonzero mode
  -K lambda_2(L), L and lambda_2 computed here with NumPy from the
  adjacency matrix. Tolerance 1e-12.
* A quadrotor hover: trim finds T = m g (1e-9), A and B equal the textbook
  hover model (Mahony, Kumar & Corke 2012) exactly, and an LQR gain from
  python-control on the linearisation brings a perturbed hover of the
  nonlinear diagram back (position error below 1e-3 m after 10 s).
* python-control on the models: poles, step response and Bode magnitude
  of a follower's distance channel against exp(-K t) and |jw/(jw + K)|,
  root locus of the hover's altitude channel against the quadratic's roots.
"""

import os

import numpy as np
import pytest

import avblocks as av

from ._diagrams import (
    ALPHA_REF,
    K_ALPHA,
    K_L,
    L_REF,
    LEADER,
    D,
    consensus_ring,
    formation,
    formation_steady_poses,
    ring_adjacency,
)

if os.environ.get("CI"):
    import control
    import jax  # noqa: F401
else:
    pytest.importorskip("jax")
    control = pytest.importorskip("control")
pytestmark = pytest.mark.jax


def formation_poles(k_l, k_alpha, v0, d):
    """The closed form of the docs page: the leader's three zeros, and per
    follower -K_l, -K_alpha and -v0 / d."""
    poles = [0.0, 0.0, 0.0]
    for i in range(1, len(k_l)):
        poles += [-k_l[i], -k_alpha[i], -v0 / d]
    return np.sort(poles)


def test_formation_poles_against_the_gains_equal_the_closed_form():
    lin = av.analysis.Linearizer(formation(v0=0.8), inputs=["form.cmd_in"],
                                 outputs=["form.error"])
    m = lin()
    # a steady state: the errors are zero, everything moves with the leader
    np.testing.assert_allclose(m.y0, 0.0, atol=1e-12)
    v = m.f0.reshape(4, 3)
    np.testing.assert_allclose(v, np.tile(v[0], (4, 1)), atol=1e-12)
    np.testing.assert_allclose(np.hypot(v[0, 0], v[0, 1]), 0.8, atol=1e-12)
    ev = m.poles()
    assert np.max(np.abs(ev.imag)) < 1e-9
    np.testing.assert_allclose(ev.real, formation_poles(K_L, K_ALPHA, 0.8, D), atol=1e-9)
    # the gains moved, compiled once: the poles follow the closed form
    rng = np.random.default_rng(0)
    for _ in range(5):
        kl, ka = rng.uniform(0.2, 5.0, 4), rng.uniform(0.2, 5.0, 4)
        ev = lin(params={"form.k_l": kl, "form.k_alpha": ka}).poles()
        np.testing.assert_allclose(ev.real, formation_poles(kl, ka, 0.8, D), atol=1e-9)
    # the heading mode moves with the leader's speed and the offset d (other
    # operating points and parameters: the same compiled Jacobian)
    for v0, d in ((0.3, 0.1), (1.5, 0.25)):
        pose = formation_steady_poses(LEADER, L_REF, ALPHA_REF, d, [0.0, 0.0, -1.0])
        ev = lin(at={"fleet.pose": pose},
                 params={"form.d": d, "lead.value": np.tile([v0, 0.0], (4, 1))}).poles()
        np.testing.assert_allclose(ev.real, formation_poles(K_L, K_ALPHA, v0, d), atol=1e-9)


def test_a_followers_distance_channel_in_python_control():
    # the perturbation enters at the reference port; the output is the error
    # e_l = (l_ref + u) - l. Closed loop: E(s)/U(s) = s / (s + K_l)
    m = av.linearize(formation(references_input=True), inputs=["form.ref"],
                     outputs=["form.error"])
    sys = m.to_control("formation")
    k = K_L[1]
    siso = sys[m.output_index("form.error[1].l"), m.input_index("form.ref[1].l_ref")]
    t = np.linspace(0.0, 4.0, 81)
    resp = control.step_response(siso, T=t)
    np.testing.assert_allclose(np.squeeze(resp.outputs), np.exp(-k * t), atol=1e-9)
    w = np.array([0.1, k, 10.0])
    mag, _phase, _w = control.frequency_response(siso, w)
    np.testing.assert_allclose(np.squeeze(mag), w / np.sqrt(w**2 + k**2), rtol=1e-9)
    # the other follower's channels do not see it
    other = sys[m.output_index("form.error[2].l"), m.input_index("form.ref[1].l_ref")]
    assert np.max(np.abs(np.squeeze(control.step_response(other, T=t).outputs))) < 1e-12


def test_consensus_on_a_ring_slowest_mode_is_k_lambda2():
    n, gain = 8, 0.7
    m = av.linearize(consensus_ring(n, gain), inputs=["agents.velocity"],
                     outputs=["agents.position"])
    adjacency = ring_adjacency(n)
    lap = np.diag(adjacency.sum(axis=1)) - adjacency
    np.testing.assert_allclose(m.A, -gain * np.kron(lap, np.eye(2)), atol=1e-12)
    lam = np.linalg.eigvalsh(lap)
    ev = np.sort(m.poles().real)[::-1]
    np.testing.assert_allclose(ev[:2], 0.0, atol=1e-12)      # the average (x and y)
    np.testing.assert_allclose(ev[2:4], -gain * lam[1], atol=1e-12)   # slowest mode
    assert lam[1] == pytest.approx(2 - 2 * np.cos(2 * np.pi / n), abs=1e-12)
    # python-control: the step response of a push on agent 0 is the integral
    # of exp(-K L s) b over [0, t], in closed form from L's eigenvectors:
    # sum_k v_k v_k^T b g_k(t), g = t for lambda = 0, (1 - exp(-K lambda t)) / (K lambda)
    sys = m.to_control()
    t = np.linspace(0.0, 6.0, 13)
    resp = control.step_response(sys, T=t, input=m.input_index("agents.velocity[0].x"))
    lam_k, vec = np.linalg.eigh(lap)
    for j, tj in enumerate(t):
        g = np.where(lam_k < 1e-12, tj,
                     (1 - np.exp(-gain * lam_k * tj)) / (gain * np.maximum(lam_k, 1e-12)))
        x_agents = vec @ (g * vec[0])               # the push is on agent 0, along x
        want = np.zeros(2 * n)
        want[0::2] = x_agents
        np.testing.assert_allclose(np.squeeze(resp.outputs)[:, j], want, atol=1e-9)


def test_consensus_trim_with_one_agent_pinned():
    n = 6
    target = np.full((n, 2), np.nan)
    target[0] = [1.0, 2.0]
    tr = av.trim(consensus_ring(n), outputs={"agents.position": target})
    assert tr.success and tr.residual < 1e-10
    np.testing.assert_allclose(tr.states["agents.position"], np.tile([1.0, 2.0], (n, 1)),
                               atol=1e-9)


def hover_diagram(mass=0.5, inertia=(0.003, 0.004, 0.005)):
    d = av.Diagram()
    q = d.add(av.vehicles.Quadrotor(np.array([[0.0, 0.0, 1.0]]), mass=mass,
                                    inertia=inertia), name="quad")
    w = d.add(av.blocks.Constant(np.zeros((1, 4))), name="w")
    d.connect(w.y, q.wrench)
    return d


def test_quadrotor_hover_trim_linearisation_and_lqr():
    m_, g, J = 0.5, 9.81, np.array([0.003, 0.004, 0.005])
    d = hover_diagram(m_, tuple(J))
    tr = av.trim(d, at={"quad.position": [[0.2, -0.1, 0.6]]}, inputs=["quad.wrench"],
                 outputs={"quad.position": [[0.0, 0.0, 1.0]]})
    np.testing.assert_allclose(tr.inputs["quad.wrench"], [[m_ * g, 0, 0, 0]], atol=1e-9)
    np.testing.assert_allclose(tr.states["quad.velocity"], 0.0, atol=1e-9)
    np.testing.assert_allclose(np.abs(tr.states["quad.attitude"][0, 0]), 1.0, atol=1e-9)
    m = av.linearize(d, at=tr, inputs=["quad.wrench"], outputs=["quad.position"])
    # the textbook hover model (Mahony et al. 2012): p' = v, v' = 2 g (q_y, -q_x),
    # q_xyz' = omega / 2, omega' = tau / J; the norm mode q_w' = -2 k_q q_w
    # (k_q = 1); thrust / m on v_z
    A = np.zeros((13, 13))
    A[0:3, 3:6] = np.eye(3)
    A[3, 8], A[4, 7] = 2 * g, -2 * g
    A[6, 6] = -2.0
    A[7:10, 10:13] = 0.5 * np.eye(3)
    B = np.zeros((13, 4))
    B[5, 0] = 1 / m_
    B[10:13, 1:4] = np.diag(1 / J)
    np.testing.assert_allclose(m.A, A, atol=1e-9)
    np.testing.assert_allclose(m.B, B, atol=1e-9)
    assert m.states[6] == "quad.attitude[0].w"
    # LQR on the linearisation, run in the nonlinear diagram from a perturbed hover
    K, _S, E = control.lqr(m.to_control(), np.eye(13), np.eye(4))
    assert np.all(np.real(E) < 0)
    x_eq, u_eq = m.x0, m.u0

    def law(t, position, velocity, attitude, rates, xp):
        x = xp.concatenate([position[0], velocity[0], attitude[0], rates[0]])
        return (u_eq - K @ (x - x_eq))[None, :]

    loop = av.Diagram()
    quad = loop.add(av.vehicles.Quadrotor(np.array([[0.3, -0.2, 0.6]]),
                                          attitude0=[0.98, 0.1, -0.1, 0.1],
                                          velocity0=[0.2, 0.0, 0.0], mass=m_,
                                          inertia=tuple(J)), name="quad")
    ctl = loop.add(av.blocks.Function(law, inputs={"position": (1, 3), "velocity": (1, 3),
                                                   "attitude": (1, 4), "rates": (1, 3)},
                                      outputs={"wrench": (1, 4)}), name="lqr")
    for p in ("position", "velocity", "attitude", "rates"):
        loop.connect(getattr(quad, p), getattr(ctl, p))
    loop.connect(ctl.wrench, quad.wrench)
    res = av.simulate(loop, 10.0, dt=0.005, log=[quad.position, quad.velocity])
    err = np.linalg.norm(res[quad.position][:, 0] - [0.0, 0.0, 1.0], axis=1)
    assert err[0] > 0.5 and err[-1] < 1e-3
    assert np.abs(res[quad.velocity][-1]).max() < 1e-3
    # python-control's root locus of the altitude channel z / T = 1 / (m s^2)
    # under a PD law k (s + 1): the roots of m s^2 + k s + k
    gz = m.to_control()[m.output_index("quad.position[0].z"),
                        m.input_index("quad.wrench[0].T")]
    gz = control.minreal(control.tf(gz), verbose=False)      # the 13 states -> 2
    np.testing.assert_allclose(gz.num[0][0], [1 / m_], rtol=1e-9)
    np.testing.assert_allclose(gz.den[0][0], [1.0, 0.0, 0.0], atol=1e-9)
    pd = control.tf([1.0, 1.0], [1.0])
    gains = np.array([0.5, 1.0, 3.0])
    loci = control.root_locus_map(pd * gz, gains).loci
    for k, row in zip(gains, loci):
        want = np.roots([m_, k, k])
        np.testing.assert_allclose(np.sort_complex(row), np.sort_complex(want), atol=1e-9)
