"""The Python API: bad arguments give an AvError naming the argument, never
a TypeError/ValueError from inside; silent garbage is refused; faults are
blamed on the block that produced them, at the time they happened."""

import copy
import math

import numpy as np
import pytest

import avblocks as av
from avblocks.core.errors import ParameterTypeError, PortAttributeError


def ramp(fn=None, n=3, solver_fn=None):
    """c (ones) -> ctl (Function fn) -> veh (Integrator): veh.y(t) = t."""
    d = av.Diagram()
    c = d.add(av.blocks.Constant(np.ones((n, 2))), name="c")
    f = d.add(av.blocks.Function(fn or (lambda t, x: x), inputs={"x": (n, 2)},
                                 outputs={"y": (n, 2)}), name="ctl")
    i = d.add(av.blocks.Integrator(np.zeros((n, 2))), name="veh")
    d.connect(c.y, f.x)
    d.connect(f.y, i.u)
    return d


@pytest.mark.parametrize("kw,param", [
    ({"seed": None}, "seed"), ({"seed": "abc"}, "seed"), ({"seed": -1}, "seed"),
    ({"seed": 1.5}, "seed"), ({"t0": None}, "t0"), ({"t0": math.inf}, "t0"),
    ({"log_every": math.nan}, "log_every"), ({"log_every": 0}, "log_every"),
    ({"log_every": "2"}, "log_every"), ({"log": 5}, "log"), ({"log": [1, 2]}, "log"),
    ({"max_log_bytes": None}, "max_log_bytes"), ({"max_log_bytes": -1}, "max_log_bytes"),
    ({"t_final": None}, "t_final"), ({"t_final": "1"}, "t_final"),
    ({"t_final": math.nan}, "t_final"), ({"t_final": -1.0}, "t_final"),
    ({"realtime": "fast"}, "realtime"), ({"realtime": 0}, "realtime"),
    ({"progress": "yes"}, "progress"), ({"check_finite": "no"}, "check_finite"),
    ({"dt": 0}, "dt"), ({"dt": "x"}, "dt"), ({"dt": math.inf}, "dt"),
])
def test_bad_simulate_arguments_are_parameter_errors(kw, param):
    args = {"t_final": 1.0, "dt": 0.1, **kw}
    with pytest.raises(av.ParameterError) as ei:
        av.simulate(ramp(), **args)
    assert ei.value.param == param


def test_t_final_must_be_a_whole_number_of_steps():
    with pytest.raises(av.ParameterError, match=r"e\.g\. 0\.9 or 1\.2"):
        av.simulate(ramp(), 1.0, dt=0.3)
    with pytest.raises(av.ParameterError, match="dt is longer than the whole run"):
        av.simulate(ramp(), 0.1, dt=0.3)
    # rounding noise is not a mismatch: 1.0 / 0.1 = 10.000000000000002
    res = av.simulate(ramp(), 1.0, dt=0.1, log=["veh.y"])
    assert res.t[-1] == pytest.approx(1.0) and len(res.t) == 11
    np.testing.assert_allclose(res["veh.y"][:, 0, 0], res.t, atol=1e-12)
    # t_final == t0: the initial sample only
    assert len(av.simulate(ramp(), 0.0, dt=0.1).t) == 1


def test_cli_seed_abc_is_one_line(tmp_path, capsys):
    from avblocks.cli import main
    rc = main(["run", "waypoints", "--set", "simulation.seed=abc", "--quiet",
               "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert rc == 2 and "parameter 'seed'" in err and err.count("\n") == 1


@pytest.mark.parametrize("make", [
    lambda: av.controllers.CyclicPursuit("a"),
    lambda: av.controllers.CyclicPursuit(-3),
    lambda: av.blocks.ZeroOrderHold("x"),
    lambda: av.blocks.ZeroOrderHold(period=[1, 2]),
    lambda: av.environment.Neighbors(-2, 1.0),
    lambda: av.vehicles.Unicycle(np.zeros((2, 3)), v_max="fast"),
    lambda: av.vehicles.Unicycle(np.zeros((2, 3)), not_an_argument=1),
    lambda: av.viz.Scope("u", every="often"),
    lambda: av.blocks.Constant(object()),
])
def test_constructor_errors_are_av_errors(make):
    with pytest.raises(av.AvError) as ei:
        make()
    assert ei.value.block is not None or ei.value.param is not None


def test_unknown_keyword_is_still_a_type_error():
    with pytest.raises(TypeError) as ei:
        av.vehicles.Unicycle(np.zeros((2, 3)), not_an_argument=1)
    assert isinstance(ei.value, ParameterTypeError)
    assert "not_an_argument" in str(ei.value) and "pose0" in str(ei.value)


def test_negative_port_sizes_are_refused():
    b = av.Block()
    with pytest.raises(av.ShapeError, match="negative agent count"):
        b.declare_input("u", (-3, 2))
    with pytest.raises(av.ShapeError):
        b.declare_output("y", (2.5, 2))


def test_ports_on_the_block_object_say_use_the_handle():
    blk = av.blocks.Constant(np.ones((2, 2)))
    with pytest.raises(PortAttributeError, match="handle Diagram.add returned"):
        blk.y                                   # noqa: B018
    with pytest.raises(AttributeError):
        blk.not_a_port                          # noqa: B018
    assert not hasattr(blk, "also_not")


def test_a_block_belongs_to_one_diagram():
    blk = av.blocks.Constant(np.ones((2, 2)))
    d1, d2 = av.Diagram(), av.Diagram()
    d1.add(blk, name="c")
    with pytest.raises(av.WiringError, match="already in another diagram"):
        d2.add(blk, name="c")
    d2.add(copy.deepcopy(blk), name="c")       # a copy is a new block
    del d1
    import gc
    gc.collect()
    av.Diagram().add(blk, name="c")              # its old diagram is gone


def test_function_output_shape_is_checked_on_every_call():
    d = ramp(lambda t, x: x if t < 0.45 else x[:1])
    with pytest.raises(av.SimulationError, match=r"block 'ctl'.*expected \(3, 2\), "
                       r"found \(1, 2\)") as ei:
        av.simulate(d, 1.0, dt=0.1, log=["veh.y"])
    r = ei.value.results
    assert r.t[-1] == pytest.approx(0.4)
    np.testing.assert_allclose(r["veh.y"][:, 0, 0], r.t, atol=1e-12)


def test_nan_from_a_controller_is_blamed_on_the_controller():
    d = ramp(lambda t, x: x * np.nan if t > 0.45 else x)
    with pytest.raises(av.SimulationError) as ei:
        av.simulate(d, 1.0, dt=0.1, log=["veh.y"])     # ctl.y not logged
    e = ei.value
    assert e.block == "ctl" and e.port == "y"
    assert e.time == pytest.approx(0.5)
    np.testing.assert_allclose(e.results["veh.y"][:, 0, 0], e.results.t, atol=1e-12)


@pytest.mark.parametrize("solver", ["RK45", "DOP853", "LSODA", "Radau"])
def test_solve_ivp_fault_reported_at_its_time_with_samples(solver):
    def boom(t, x):
        if t > 1.3:
            raise RuntimeError("sensor died")
        return x
    with pytest.raises(av.SimulationError, match="sensor died") as ei:
        av.simulate(ramp(boom), 2.0, dt=0.1, log=["veh.y"], solver=solver)
    e = ei.value
    assert e.block == "ctl"
    assert 1.2 <= e.time <= 1.3 + 1e-9
    r = e.results
    assert len(r.t) >= 13 and r.t[-1] == pytest.approx(e.time)
    np.testing.assert_allclose(r["veh.y"][:, 0, 0], r.t, rtol=1e-6, atol=1e-9)


def test_results_save_and_load_errors_are_av_errors(tmp_path):
    res = av.simulate(ramp(), 0.5, dt=0.1, log=["veh.y"])
    with pytest.raises(av.AvError, match="no folder"):
        res.save(tmp_path / "missing" / "r.nc")
    with pytest.raises(av.AvError, match="unknown format"):
        res.save(tmp_path / "r.csv")
    bad = tmp_path / "bad.nc"
    bad.write_bytes(b"not a netcdf file at all")
    with pytest.raises(av.AvError, match="cannot read"):
        av.Results.load(bad)
    good = res.save(tmp_path / "r.nc")
    trunc = tmp_path / "trunc.nc"
    trunc.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    with pytest.raises(av.AvError, match="cannot read"):
        av.Results.load(trunc)
    back = av.Results.load(good)
    np.testing.assert_array_equal(back["veh.y"], res["veh.y"])
    z = res.save(tmp_path / "r.zarr")
    res.save(z)                                  # overwrite in place
    np.testing.assert_array_equal(av.Results.load(z)["veh.y"], res["veh.y"])
    assert not list(tmp_path.glob(".*part*"))


def test_absurd_port_and_seed_counts_are_refused_before_allocating():
    """Found by the constructor fuzz: Mux(10**30) built a list of 10^30 port
    names until the machine ran out of memory."""
    import avblocks as av
    from avblocks.sweep.spec import SweepError, normalise_seeds
    for cls in (av.blocks.Mux, av.blocks.Concatenate):
        with pytest.raises(av.ParameterError, match="number of ports"):
            cls(10**30)
    assert len(av.blocks.Mux(3).names) == 3
    with pytest.raises(SweepError, match="seeds"):
        normalise_seeds(10**30)
    assert normalise_seeds(3) == [0, 1, 2]
