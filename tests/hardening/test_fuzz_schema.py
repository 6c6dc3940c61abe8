"""Property-based tests over the whole scenario schema (issue 22).

Scenario dicts are generated from valid seeds (a small complete scenario
using every section, ``outcome:``/``figures:``/``report:`` included, and the
built-in YAML scenarios) and mutated: values swapped for wrong types, NaN,
inf, huge numbers, strings where numbers go, mappings where names go, deep
nesting; unknown keys added; keys removed. Each is written as a YAML file
and taken through what ``avblocks run`` does: load, build, check the
report sections, a run of two steps, then the outcome line and the figures.
Every step must succeed or end in an avblocks error (``AvError`` with a
message), never another exception.

A fast profile runs in every CI run (200 examples; figures are drawn for
about one in eight, as drawing costs a few tenths of a second); the long
one (1,500 examples, figures always) is marked slow.
``AVBLOCKS_FUZZ_EXAMPLES`` sets the fast profile's count.
"""

import copy
import math
import os
import tempfile
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

import avblocks as av
from avblocks.scenarios.loader import builtin_dir
from avblocks.scenarios.targets import load_any

FAST = settings(max_examples=int(os.environ.get("AVBLOCKS_FUZZ_EXAMPLES", 200)),
                deadline=None, database=None, suppress_health_check=list(HealthCheck))
LONG = settings(max_examples=1500, deadline=None, database=None,
                suppress_health_check=list(HealthCheck))

TINY = {
    "name": "tiny",
    "description": "three unicycles to their goals",
    "parameters": {"agents": 3, "seed": 1, "speed": 1.0},
    "blocks": {
        "fleet": {"type": "vehicles.Unicycle",
                  "pose0": {"random_poses": {"n": "$agents", "area": [5, 5], "seed": "$seed"}}},
        "drive": {"type": "controllers.PointToPoint",
                  "waypoints": {"random_waypoints": {"n": "$agents", "count": 2,
                                                     "area": [5, 5], "seed": "$seed"}},
                  "v_max": "$speed", "gain": 1.0},
    },
    "wires": [["fleet.pose", "drive.pose"], ["drive.cmd", "fleet.cmd"]],
    "simulation": {"t_final": 1.0, "dt": 0.1, "solver": "rk4", "log_every": 1,
                   "log": ["fleet.pose", "drive.done"], "seed": "$seed"},
    "params": {"drive.gain": 2.0},
    "movie": {"trail": 1.0, "color": "drive.done"},
    "outcome": [
        {"metric": "all_true", "signal": "drive.done", "what": "arrived"},
        {"metric": "min_distance", "signal": "fleet.pose", "label": "closest"},
        {"metric": "final_mean", "signal": "fleet.pose", "component": 0, "unit": "m"},
    ],
    "figures": [
        {"plot": "trajectories", "file": "t.png", "waypoints": "drive", "title": "T",
         "color": "drive.done", "figsize": [3, 3], "max_points": 20},
        {"plot": "signals", "file": "s.svg", "signals": ["fleet.pose"], "components": [0],
         "figsize": [3, 3]},
        {"plot": "fraction", "file": "f.png", "signal": "drive.done", "label": "done"},
    ],
}
SEEDS = [TINY] + [yaml.safe_load(p.read_text())
                  for p in sorted(builtin_dir().glob("*.yaml"))]
# names that mean something somewhere in the schema: unknown keys that look right
KEYS = ["type", "signal", "signals", "file", "plot", "metric", "log", "t_final", "dt",
        "pose", "waypoints", "agents", "report", "outcome", "figures", "blocks", "wires",
        "seed", "title", "what", "component", "figsize", "n", "area", "__class__",
        "zeros", "world", "random_poses", "fleet.pose", "drive.gain", "$agents", ""]
SCALARS = st.one_of(
    st.sampled_from([None, True, False, 0, 1, -1, 3, 2**31, 2**63, 10**30, -(10**30),
                     0.0, -0.0, 1e-300, 1e300, math.nan, math.inf, -math.inf, "", "abc",
                     "1", "1e400", "$agents", "$nope", "${seed}", "fleet.pose",
                     "drive.done", "drive", "x.png", "!!str png", "png", "../x.png",
                     "/etc/hostname", "vehicles.Unicycle", "nest", "trajectories",
                     "all_true", "rk4", "é\u0000", "a" * 300]),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=12),
)


def _nest(depth, inner):
    v = inner
    for k in range(depth):
        v = [v] if k % 2 else {"a": v}
    return v


HOSTILE = st.one_of(
    SCALARS,
    st.lists(SCALARS, max_size=4),
    st.dictionaries(st.sampled_from(KEYS), SCALARS, max_size=3),
    st.builds(_nest, st.integers(2, 60), SCALARS),
    st.lists(st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=2,
                      max_size=3), max_size=4),
)


def _containers(v, path=()):
    """Every (path, container) inside v, v itself first."""
    out = [(path, v)] if isinstance(v, (dict, list)) and v else []
    items = v.items() if isinstance(v, dict) else enumerate(v) if isinstance(v, list) else ()
    for k, x in items:
        out += _containers(x, (*path, k))
    return out


def _mutate(data, scenario):
    for _ in range(data.draw(st.integers(1, 4), label="mutations")):
        spots = _containers(scenario)
        if not spots:
            return data.draw(HOSTILE, label="whole file")
        path, c = data.draw(st.sampled_from(spots), label="where")
        keys = list(c) if isinstance(c, dict) else list(range(len(c)))
        kind = data.draw(st.sampled_from(["replace", "replace", "stringify", "add", "drop",
                                          "wrap"]), label="kind")
        k = data.draw(st.sampled_from(keys), label="key")
        if kind == "replace":
            c[k] = data.draw(HOSTILE, label="value")
        elif kind == "stringify":
            c[k] = str(c[k])
        elif kind == "wrap":
            c[k] = data.draw(st.sampled_from([[c[k]], {"a": c[k]}, {k: c[k]}]), label="w")
        elif kind == "add" and isinstance(c, dict):
            c[data.draw(st.sampled_from(KEYS), label="new key")] = data.draw(HOSTILE,
                                                                           label="value")
        elif kind == "add":
            c.append(data.draw(HOSTILE, label="value"))
        elif isinstance(c, dict):
            del c[k]
        else:
            c.pop(k)
    return scenario


def _clean(fn):
    """fn(); an AvError with a message is a clean failure (None)."""
    try:
        return fn()
    except av.AvError as e:
        assert str(e).strip(), repr(e)
        return None


def _schema_property(data, draw_figures=True):
    seed = data.draw(st.sampled_from(range(len(SEEDS))), label="seed scenario")
    scenario = _mutate(data, copy.deepcopy(SEEDS[seed]))
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "s.yaml"
        try:
            p.write_text(yaml.safe_dump(scenario, allow_unicode=True))
        except (yaml.YAMLError, RecursionError, UnicodeEncodeError):
            return                      # not writable as YAML: not a file a user has
        out = Path(tmp) / "out"
        loaded = _clean(lambda: load_any(str(p), {}, out))
        event("loaded" if loaded is not None else "refused at load")
        if loaded is None:
            return
        d, sim, _name, _movie = loaded
        hooks = loaded.hooks
        dt = sim.get("dt", 0.01)
        try:
            t_final = 2 * float(dt)
        except (TypeError, ValueError):
            t_final = 0.02
        if not (isinstance(dt, (int, float)) and math.isfinite(t_final) and t_final > 0):
            t_final = 0.02
        sim = {**sim, "t_final": sim.get("t0", 0.0) + t_final, "progress": False}
        sim.pop("realtime", None)
        res = _clean(lambda: av.simulate(d, **sim))
        if res is None or not len(res.t):
            return
        if hooks is not None and hooks.outcome is not None:
            got = _clean(lambda: hooks.outcome(res))
            if got is not None:
                line, numbers = got
                assert isinstance(line, str) and isinstance(numbers, dict)
        if hooks is not None and hooks.figures is not None and draw_figures:
            import matplotlib.pyplot as plt
            try:
                files = _clean(lambda: hooks.figures(res, out))
            finally:
                plt.close("all")
            for f in files or []:             # every figure lands in the output folder
                assert Path(f).resolve().is_relative_to(out.resolve()) and Path(f).is_file()


@FAST
@given(st.data())
def test_fuzz_scenario_schema(data):
    _schema_property(data, data.draw(st.sampled_from([True] + [False] * 7),
                                     label="draw figures"))


@pytest.mark.slow
@LONG
@given(st.data())
def test_fuzz_scenario_schema_long(data):
    _schema_property(data)


SET_KEYS = ["agents", "seed", "speed", "density", "simulation.log", "simulation.solver",
            "simulation.log_every", "simulation.seed", "simulation.nope", "drive.gain",
            "drive.nope", "nope.gain", "fleet.pose0", "log_every", "solver", "x", "",
            "simulation.", "."]
CLI_FAST = settings(max_examples=40, deadline=None, database=None,
                    suppress_health_check=list(HealthCheck))
CLI_LONG = settings(max_examples=300, deadline=None, database=None,
                    suppress_health_check=list(HealthCheck))


def _cli_property(data):
    """The same files through ``avblocks run`` (two steps of 0.1 s, no
    pacing): exit status 0, 2 (refused) or 3 (run failed or a file could
    not be written, results kept), one error line per problem, never a
    traceback."""
    import contextlib
    import io

    from avblocks.cli import main
    seed = data.draw(st.sampled_from(range(len(SEEDS))), label="seed scenario")
    scenario = _mutate(data, copy.deepcopy(SEEDS[seed]))
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "s.yaml"
        try:
            p.write_text(yaml.safe_dump(scenario, allow_unicode=True))
        except (yaml.YAMLError, RecursionError, UnicodeEncodeError):
            return
        sets = []
        for _ in range(data.draw(st.integers(0, 2), label="--set count")):
            key = data.draw(st.sampled_from(SET_KEYS), label="--set key")
            val = data.draw(HOSTILE, label="--set value")
            try:
                text = yaml.safe_dump(val, default_flow_style=True).strip()
            except (yaml.YAMLError, RecursionError):
                continue
            sets += ["--set", f"{key}={text.removesuffix('...').strip()}"]
        out, err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            rc = main(["run", str(p), "--out", str(Path(tmp) / "o"), "--quiet", *sets,
                       "--set", "simulation.dt=0.1",
                       "--set", "simulation.realtime=null", "--t-final", "0.2"])
        import matplotlib.pyplot as plt
        plt.close("all")
        event(f"exit status {rc}")
        assert rc in (0, 2, 3), (rc, err.getvalue())
        assert "Traceback" not in err.getvalue()
        if rc == 2:
            assert err.getvalue().startswith("avblocks: error: ")


@CLI_FAST
@given(st.data())
def test_fuzz_scenario_schema_cli(data):
    _cli_property(data)


@pytest.mark.slow
@CLI_LONG
@given(st.data())
def test_fuzz_scenario_schema_cli_long(data):
    _cli_property(data)


def test_seeds_are_valid_and_their_reports_run(tmp_path):
    """The unmutated seed runs clean: its outcome numbers are the results'."""
    p = tmp_path / "tiny.yaml"
    p.write_text(yaml.safe_dump(TINY))
    loaded = load_any(str(p), {}, tmp_path / "out")
    d, sim, *_ = loaded
    res = av.simulate(d, **sim)
    line, numbers = loaded.hooks.outcome(res)
    pose = np.asarray(res["fleet.pose"])
    assert numbers["fleet_pose_final_mean"] == pytest.approx(pose[-1, :, 0].mean())
    gaps = [np.linalg.norm(pose[k, i, :2] - pose[k, j, :2]) for k in range(len(res.t))
            for i in range(3) for j in range(i + 1, 3)]
    assert numbers["closest_approach_m"] == pytest.approx(min(gaps))
    files = loaded.hooks.figures(res, tmp_path / "out")
    assert sorted(f.name for f in files) == ["f.png", "s.svg", "t.png"]


# ------------------------------------------------ what the fuzzing found (regressions)
def test_generator_failing_inside_is_a_scenario_error(tmp_path):
    """nest_poses with density 0 divided by zero inside the generator."""
    nest = yaml.safe_load((builtin_dir() / "nest.yaml").read_text())
    nest["blocks"]["bees"]["pose0"]["nest_poses"]["density"] = False
    p = tmp_path / "n.yaml"
    p.write_text(yaml.safe_dump(nest))
    with pytest.raises(av.ScenarioError) as e:
        load_any(str(p), {}, tmp_path / "out")
    assert e.value.entry == "blocks.bees.pose0" and "nest_poses" in str(e.value)


MOVIE_BASE = """
blocks:
  fleet: {type: vehicles.Unicycle, pose0: {zeros: {shape: [2, 3]}}}
  c: {type: blocks.Constant, value: [[1.0, 0.0], [1.0, 0.1]]}
wires: [[c.y, fleet.cmd]]
simulation: {t_final: 0.5, dt: 0.1}
"""


@pytest.mark.parametrize("movie, extra, words", [
    ('{obstacles: [[1, 2], "x"]}', [], "movie: the trajectory figure (pose, obstacles) failed"),
    ("{trail: abc}", ["--movie", "m.gif"], "a 'movie:' option is wrong"),
])
def test_bad_movie_options_keep_the_results(tmp_path, monkeypatch, capsys, movie, extra,
                                            words):
    from avblocks.cli import main
    (tmp_path / "m.yaml").write_text(MOVIE_BASE + f"movie: {movie}\n")
    monkeypatch.chdir(tmp_path)
    rc = main(["run", "m.yaml", "--out", "o", "--quiet", *extra])
    err = capsys.readouterr().err
    assert rc == 3 and words in err and "kept: o/results.nc" in err, err
    assert av.Results.load(tmp_path / "o" / "results.nc").t[-1] == pytest.approx(0.5)


@pytest.mark.parametrize("section", ["simulation: null", "simulation: {}", ""])
def test_set_simulation_on_an_empty_simulation_section(tmp_path, section):
    """``--set simulation.dt=...`` on a file whose simulation section is null."""
    p = tmp_path / "m.yaml"
    p.write_text(MOVIE_BASE.replace("simulation: {t_final: 0.5, dt: 0.1}", section))
    d, sim, *_ = load_any(str(p), {"simulation.dt": 0.25, "t_final": 0.5}, tmp_path / "o")
    assert sim["dt"] == 0.25 and sim["t_final"] == 0.5
    assert av.simulate(d, **sim).t.tolist() == [0.0, 0.25, 0.5]
