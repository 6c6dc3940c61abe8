"""Every vehicle block passes the core conformance checker at N=1 and N=7,
runs 10,000 agents, and traces under JAX."""

from __future__ import annotations

import numpy as np
import pytest

import avblocks as av
from avblocks.core.check import check_block
from avblocks.vehicles import (
    Ackermann,
    Blimp,
    DiffDrive,
    DoubleIntegrator,
    Quadrotor,
    QuadrotorVelocityControl,
    SingleIntegrator,
    Unicycle,
    Unicycle2,
)


def _p(n, k=3):
    return np.linspace(0, 1, n * k).reshape(n, k)


FACTORIES = {
    "unicycle": lambda n: Unicycle(_p(n), v_max=1.0, omega_max=np.arange(1, n + 1)),
    "unicycle_sat": lambda n: Unicycle(_p(n), v_max=1.0, saturation_output=True),
    "unicycle2": lambda n: Unicycle2(_p(n), mass=np.arange(1, n + 1), inertia=0.2,
                                     lin_damping=0.1, f_max=2.0),
    "diffdrive": lambda n: DiffDrive(_p(n), wheel_speed_max=10.0),
    "ackermann": lambda n: Ackermann(_p(n), v_max=3.0),
    "ackermann_lag": lambda n: Ackermann(_p(n), steer_tau=0.2, steer_rate_max=1.0),
    "single2": lambda n: SingleIntegrator(_p(n, 2), v_max=1.0),
    "single3": lambda n: SingleIntegrator(_p(n), dim=3),
    "double2": lambda n: DoubleIntegrator(_p(n, 2), a_max=1.0, v_max=2.0, drag=0.1),
    "double3_force": lambda n: DoubleIntegrator(_p(n), input="force", mass=2.0),
    "quad_wrench": lambda n: Quadrotor(_p(n), thrust_max=20.0, torque_max=(1, 1, 0.5),
                                       drag=0.1, mass=np.linspace(0.5, 1.5, n)),
    "quad_rotors_x": lambda n: Quadrotor(_p(n), input="rotors", rotor_max=5.0),
    "quad_rotors_plus": lambda n: Quadrotor(_p(n), input="rotors", frame="+"),
    "quad_ctrl": lambda n: QuadrotorVelocityControl(n),
    "quad_ctrl_rotors": lambda n: QuadrotorVelocityControl(n, output="rotors",
                                                           rotor_max=5.0),
    "blimp": lambda n: Blimp(_p(n), thrust_max=(1.0, 1.0), torque_max=0.1),
    "blimp_linear": lambda n: Blimp(_p(n), drag="linear", net_lift=0.05),
}


def _unit_quat_inputs(n, b):
    gen = np.random.default_rng(0)
    u = {k: gen.normal(size=p.shape) for k, p in b.input_ports.items()}
    if "attitude" in u:
        u["attitude"] = u["attitude"] / np.linalg.norm(u["attitude"], axis=-1, keepdims=True)
    return u


@pytest.mark.parametrize("name", sorted(FACTORIES))
def test_check_block(name):
    rep = check_block(FACTORIES[name], ns=(1, 7), inputs=_unit_quat_inputs)
    assert rep.ok and rep.checked_n == [1, 7]


@pytest.mark.parametrize("name", sorted(FACTORIES))
def test_read_only_inputs_and_state(name):
    """Stronger than comparing copies: any in-place write raises."""
    b = FACTORIES[name](7)
    u = _unit_quat_inputs(7, b)
    x = b.initial_state()
    for a in (*u.values(), *x.values()):
        a.flags.writeable = False
    y = b.output(0.0, x, {k: v for k, v in u.items() if k in b.feedthrough}, np)
    for k, p in b.output_ports.items():
        assert np.shape(y[k]) == p.shape
    if b.continuous_states:
        dx = b.derivative(0.0, x, u, np)
        assert {k: np.shape(v) for k, v in dx.items()} == \
            {k: p.shape for k, p in b.continuous_states.items()}


@pytest.mark.parametrize("name", ["unicycle", "unicycle2", "diffdrive", "ackermann_lag",
                                  "double2", "quad_rotors_x", "blimp"])
def test_ten_thousand_agents_in_a_diagram(name):
    n = 10_000
    b = FACTORIES[name](n)
    (inp, port), = b.input_ports.items()
    d = av.Diagram()
    v = d.add(b, name="v")
    c = d.add(av.blocks.Constant(np.full(port.shape, 0.1)), name="c")
    d.connect(c.y, v.port(inp))
    out = next(iter(b.output_ports))
    res = av.simulate(d, 0.05, dt=0.01, log=[v.port(out)], progress=False)
    assert res[v.port(out)].shape == (6, *b.output_ports[out].shape)
    assert np.all(np.isfinite(res[v.port(out)]))


@pytest.mark.jax
@pytest.mark.parametrize("name", ["unicycle_sat", "unicycle2", "diffdrive", "ackermann_lag",
                                  "double2", "quad_wrench", "quad_rotors_plus",
                                  "quad_ctrl_rotors", "blimp"])
def test_traces_under_jax(name):
    """The block math uses only ``xp``: it runs under jax.numpy and agrees."""
    jax = pytest.importorskip("jax")
    jax.config.update("jax_enable_x64", True)
    jnp = jax.numpy
    b = FACTORIES[name](7)
    u = _unit_quat_inputs(7, b)
    x = b.initial_state()
    uf = {k: v for k, v in u.items() if k in b.feedthrough}
    ref = b.output(0.0, x, uf, np)
    got = jax.jit(lambda xx, uu: b.output(0.0, xx, uu, jnp))(x, uf)
    for k in ref:
        np.testing.assert_allclose(np.asarray(got[k]), ref[k], atol=1e-12)
    if b.continuous_states:
        ref = b.derivative(0.0, x, u, np)
        got = jax.jit(lambda xx, uu: b.derivative(0.0, xx, uu, jnp))(x, u)
        for k in ref:
            np.testing.assert_allclose(np.asarray(got[k]), ref[k], atol=1e-12)


def test_parameter_errors_name_block_and_parameter():
    with pytest.raises(av.ParameterError, match="mass"):
        Unicycle2(np.zeros((2, 3)), mass=[1.0, -1.0])
    with pytest.raises(av.ParameterError, match="wheel_speed_max"):
        DiffDrive(np.zeros((2, 3)), wheel_speed_max=-1.0)
    with pytest.raises(av.ParameterError, match="input"):
        Quadrotor(np.zeros((1, 3)), input="thrust")
    with pytest.raises(av.ParameterError, match="frame"):
        Quadrotor(np.zeros((1, 3)), frame="h")
    with pytest.raises(av.ParameterError, match="inertia"):
        Quadrotor(np.zeros((2, 3)), inertia=np.ones((3, 3)))
    with pytest.raises(av.ParameterError, match="attitude0"):
        Quadrotor(np.zeros((1, 3)), attitude0=(0, 0, 0, 0))
