"""Numeric parameters: declared, read and set by name, validated, applied at
the next major step, recorded; simulate(params=, x0=) restore the blocks."""

import numpy as np
import pytest

import avblocks as av


def _ramp(k=2.0):
    d = av.Diagram()
    c = d.add(av.blocks.Constant([[1.0]]), name="c")
    g = d.add(av.blocks.Gain(k), name="g")
    i = d.add(av.blocks.Integrator([[0.0]]), name="i")
    d.connect(c.y, g.u)
    d.connect(g.y, i.u)
    return d, i


def test_declared_and_addressed_by_name():
    d, _ = _ramp()
    cd = d.build()
    assert "g.k" in cd.parameters()
    assert cd.get_param("g.k") == pytest.approx(2.0)
    cd.set_param("g.k", 3.0)
    assert cd.get_param("g.k") == pytest.approx(3.0)


def test_bad_name_and_value_are_clear_errors():
    d, _ = _ramp()
    cd = d.build()
    with pytest.raises(av.ParameterError, match="did you mean"):
        cd.set_param("g.kk", 1.0)
    with pytest.raises(av.ParameterError, match="no such numeric parameter"):
        cd.set_param("nope.k", 1.0)
    with pytest.raises(av.ParameterError, match="NaN"):
        cd.set_param("g.k", float("nan"))
    with pytest.raises(av.ParameterError, match="shape"):
        cd.set_param("g.k", [1.0, 2.0])


def test_bounds_are_enforced():
    class B(av.Block):
        def __init__(self):
            super().__init__()
            self.declare_parameter("r", 1.0, bounds=(0.0, 5.0))
    b = B()
    b.set_parameter("r", 5.0)
    with pytest.raises(av.ParameterError, match="upper bound"):
        b.set_parameter("r", 5.1)
    with pytest.raises(av.ParameterError, match="lower bound"):
        b.set_parameter("r", -1)


def test_simulate_params_and_x0_are_used_then_restored():
    d, i = _ramp(2.0)
    res = av.simulate(d, 1.0, dt=0.1, log=[i.y], params={"g.k": 5.0},
                      x0={"i.x": [[1.0]]})
    # y(t) = 1 + 5 t exactly (RK4 on a constant rate)
    assert res[i.y][-1, 0, 0] == pytest.approx(6.0, abs=1e-12)
    assert res.meta["params"] == {"g.k": 5.0}
    res2 = av.simulate(d, 1.0, dt=0.1, log=[i.y])
    assert res2[i.y][-1, 0, 0] == pytest.approx(2.0, abs=1e-12)


def test_set_param_mid_run_takes_effect_at_next_major_step():
    d, i = _ramp(1.0)
    sim = av.Simulator(d, dt=0.1)
    sim.init()
    for _ in range(5):
        sim.step()
    sim.set_param("g.k", 3.0)      # queued: applies at the start of step 6
    assert sim.get_param("g.k") == pytest.approx(1.0)
    for _ in range(5):
        sim.step()
    # 0.5 s at rate 1, then 0.5 s at rate 3
    assert float(sim.value(i.y)[0, 0]) == pytest.approx(0.5 + 1.5, abs=1e-12)
    assert sim.param_changes == [(pytest.approx(0.5), "g.k", 3.0)]


def test_x0_wrong_shape_is_refused():
    d, _ = _ramp()
    with pytest.raises(av.ParameterError, match="wrong shape"):
        av.simulate(d, 1.0, dt=0.1, x0={"i.x": [1.0, 2.0]})
    with pytest.raises(av.ParameterError, match="no such state"):
        av.simulate(d, 1.0, dt=0.1, x0={"i.nope": [[1.0]]})


def test_parameter_round_trip_in_saved_results(tmp_path):
    d, i = _ramp(2.0)
    sim_res = av.simulate(d, 0.2, dt=0.1, log=[i.y], params={"g.k": np.array(4.0)})
    sim_res.save(tmp_path / "r.nc")
    back = av.Results.load(tmp_path / "r.nc")
    assert back.meta["params"] == {"g.k": 4.0}
