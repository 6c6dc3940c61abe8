"""simulate(): NaN stops, seeding, logging, results files, real-time pacing."""

import time

import numpy as np
import pytest

import avblocks as av
from avblocks.core import rng


class Blowup(av.Block):
    """dx/dt = 1 / (T - t): x reaches inf at t = T; optional NaN output."""

    def __init__(self, T=0.5, nan_at=None):
        super().__init__()
        self.T, self.nan_at = T, nan_at
        self.declare_continuous_state("x", np.zeros((2, 1)))
        self.declare_output("y", (2, 1))

    def output(self, t, x, u, xp):
        y = x["x"]
        if self.nan_at is not None:
            y = xp.where(t >= self.nan_at, np.nan, y)
        return {"y": y}

    def derivative(self, t, x, u, xp):
        with np.errstate(divide="ignore"):
            return {"x": xp.ones_like(x["x"]) / (self.T - t) ** 3}


def test_nan_output_stops_with_block_port_time_and_keeps_log():
    d = av.Diagram()
    b = d.add(Blowup(T=10.0, nan_at=0.3), name="boom")
    with pytest.raises(av.SimulationError) as e:
        av.simulate(d, 1.0, dt=0.1, log=[b.y])
    err = e.value
    assert "block 'boom', port 'y'" in str(err)
    assert err.time == pytest.approx(0.3)
    assert err.results is not None
    assert len(err.results.t) == 3  # 0.0, 0.1, 0.2 were logged
    assert np.all(np.isfinite(err.results[b.y]))


def test_state_blowup_names_block():
    d = av.Diagram()
    d.add(Blowup(T=0.5), name="boom")
    with pytest.raises(av.SimulationError, match="boom") as e:
        av.simulate(d, 1.0, dt=0.1, solver="euler", log=["boom.y"])
    assert e.value.time == pytest.approx(0.6)


class Noise(av.Block):
    def __init__(self, n):
        super().__init__()
        self.n = n
        self.declare_random_state("key")
        self.declare_discrete_state("v", np.zeros(n))
        self.declare_output("y", (n,))

    def output(self, t, x, u, xp):
        return {"y": x["v"]}

    def update(self, t, x, u, xp):
        k, sub = rng.split(x["key"], xp)
        return {"key": k, "v": rng.normal(sub, (self.n,), xp)}


def run_noise(seed):
    d = av.Diagram()
    a = d.add(Noise(5), name="a")
    b = d.add(Noise(5), name="b")
    res = av.simulate(d, 1.0, dt=0.1, seed=seed, log=[a.y, b.y])
    return res[a.y], res[b.y]


def test_seeded_runs_are_bit_for_bit_repeatable_and_streams_differ():
    a1, b1 = run_noise(3)
    a2, b2 = run_noise(3)
    a3, _ = run_noise(4)
    assert np.array_equal(a1, a2) and np.array_equal(b1, b2)
    assert not np.array_equal(a1, b1)
    assert not np.array_equal(a1, a3)
    # the draws are standard normal
    big = np.concatenate([run_noise(s)[0][1:].ravel() for s in range(20)])
    assert abs(big.mean()) < 4 / np.sqrt(big.size) * 1.5
    assert big.std() == pytest.approx(1.0, abs=0.15)


def circle_diagram(n=2):
    d = av.Diagram()
    f = d.add(av.vehicles.Unicycle(pose0=np.zeros((n, 3))), name="fleet")
    c = d.add(av.blocks.Constant(np.tile([1.0, 0.5], (n, 1))), name="c")
    d.connect(c.y, f.cmd)
    return d, f


def test_decimation_and_results_roundtrip(tmp_path):
    d, f = circle_diagram()
    res = av.simulate(d, 2.0, dt=0.01, log=[f.pose], log_every=10)
    assert len(res.t) == 21
    assert np.allclose(res.t, np.linspace(0, 2, 21))
    ds = res.to_xarray()
    assert ds["fleet.pose"].dims == ("time", "agent", "fleet.pose.comp")
    assert list(ds["fleet.pose.comp"].values) == ["x", "y", "theta"]
    p = res.save(tmp_path / "run.nc")
    back = av.Results.load(p)
    assert np.array_equal(back["fleet.pose"], res[f.pose])
    assert np.array_equal(back.t, res.t)
    assert back.meta["solver"] == "rk4" and back.meta["steps"] == 200
    assert back.ports["fleet.pose"].labels == ("x", "y", "theta")


def test_missing_results_file_is_a_clear_error(tmp_path):
    with pytest.raises(av.AvError, match="no results file"):
        av.Results.load(tmp_path / "nope.nc")


def test_default_log_is_the_poses():
    d, f = circle_diagram()
    res = av.simulate(d, 0.1, dt=0.01)
    assert list(res.keys()) == ["fleet.pose"]


@pytest.mark.parametrize("kw,match", [
    (dict(t_final=float("nan")), "t_final"),
    (dict(t_final=1.0, dt=0.0), "dt"),
    (dict(t_final=1.0, log_every=0), "log_every"),
    (dict(t_final=1.0, realtime=-1.0), "realtime"),
    (dict(t_final=1.0, log=["fleet.nope"]), "nope"),
    (dict(t_final=1.0, log=["ghost.pose"]), "ghost"),
])
def test_bad_simulate_arguments(kw, match):
    d, _ = circle_diagram()
    with pytest.raises(av.AvError, match=match):
        av.simulate(d, **kw)


def test_realtime_pacing_takes_wall_time():
    d, f = circle_diagram()
    t0 = time.perf_counter()
    res = av.simulate(d, 0.3, dt=0.01, realtime=1.0, log=[f.pose])
    wall = time.perf_counter() - t0
    # pacing is a lower bound on wall time, not a timing assertion on speed
    assert wall >= 0.3 * 0.95
    assert res.meta["overruns"] >= 0 and "max_lateness" in res.meta
    assert res.meta["realtime_factor"] == pytest.approx(1.0, rel=0.5)


class RaisesInside(av.Block):
    def __init__(self):
        super().__init__()
        self.declare_output("y", (1,))

    def output(self, t, x, u, xp):
        if t > 0.05:
            raise RuntimeError("sensor unplugged")
        return {"y": xp.zeros(1)}


def test_exception_in_block_is_reported_with_block_and_time():
    d = av.Diagram()
    d.add(RaisesInside(), name="sensor")
    with pytest.raises(av.SimulationError, match="block 'sensor'.*sensor unplugged") as e:
        av.simulate(d, 1.0, dt=0.1, log=["sensor.y"])
    assert len(e.value.results.t) == 1


class WrongShape(av.Block):
    def __init__(self):
        super().__init__()
        self.declare_output("y", (3, 2))

    def output(self, t, x, u, xp):
        return {"y": xp.zeros((3,))}


def test_wrong_output_shape_is_caught_at_start():
    d = av.Diagram()
    d.add(WrongShape(), name="w")
    with pytest.raises(av.ShapeError,
                       match=r"block 'w', port 'y'.*expected \(3, 2\), found \(3,\)"):
        av.simulate(d, 1.0)
