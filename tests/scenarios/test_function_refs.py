"""Scenario-file values that name library functions and the generic
generators the honeybee file uses (function by name, a distance guard,
arange with a start, add, item)."""

import numpy as np
import pytest

import avblocks as av
from avblocks.scenarios import GENERATORS, Scenario
from avblocks.scenarios.loader import resolve_function


def test_a_library_function_is_resolved_by_name():
    from avblocks.scenarios.honeybee import choose_command
    assert resolve_function("avblocks.scenarios.honeybee:choose_command") is choose_command


@pytest.mark.parametrize("ref, match", [
    ("os:system", "not a module a file may name"),
    ("avblocksx.mod:f", "not a module a file may name"),
    ("avblocks.scenarios.honeybee:_capacity", "expected 'package.module:function'"),
    ("avblocks.scenarios.honeybee", "expected 'package.module:function'"),
    ("avblocks.scenarios.honeybee:MOVIE", "is not a function"),
    ("avblocks.blocks:Function", "is not a function"),         # a class: never built
    ("avblocks.nosuchmodule:f", "cannot import"),
    # names a library module imported from elsewhere (attack42: these ran)
    ("avblocks.analysis.model:dataclass", "a function of 'dataclasses'"),
    ("avblocks.viz.scene:to_rgba", "a function of 'matplotlib.colors'"),
    (["avblocks.scenarios.honeybee:choose_command"], "expected"),
])
def test_anything_else_is_refused_naming_the_entry(ref, match):
    with pytest.raises(av.ScenarioError, match=match):
        resolve_function(ref, source="s.yaml", where="blocks.f.fn")


def _choose_scenario(fn):
    blocks = {
        "mode": {"type": "blocks.Constant", "value": {"arange": {"n": 3}}},
        "search": {"type": "blocks.Constant", "value": [[1.0, 1.0], [2.0, 2.0], [3.0, 3.0]]},
        "home": {"type": "blocks.Constant", "value": [[4.0, 4.0], [5.0, 5.0], [6.0, 6.0]]},
        "inside": {"type": "blocks.Constant", "value": [[7.0, 7.0], [8.0, 8.0], [9.0, 9.0]]},
        "walk": {"type": "blocks.Constant", "value": [[0.5, -0.5]]},
        "f": {"type": "blocks.Function", "fn": {"function": fn},
              "inputs": {k: None for k in ("mode", "search", "home", "inside", "walk")},
              "outputs": {"cmd": [4, 2], "flag": None}},
    }
    wires = [[f"{k}.y", f"f.{k}"] for k in ("mode", "search", "home", "inside", "walk")]
    return Scenario({"name": "f", "blocks": blocks, "wires": wires,
                     "simulation": {"t_final": 0.1, "dt": 0.1, "log": ["f.cmd", "f.flag"]}},
                    "f.yaml")


def test_a_function_block_named_in_a_file_runs_the_named_function():
    d, sim = _choose_scenario("avblocks.scenarios.honeybee:choose_command").build()
    res = av.simulate(d, progress=False, **sim)
    # agent i in mode i takes row i of search / home / inside; the walker follows
    np.testing.assert_array_equal(np.asarray(res["f.cmd"])[-1],
                                  [[1.0, 1.0], [5.0, 5.0], [9.0, 9.0], [0.5, -0.5]])
    assert np.asarray(res["f.flag"])[-1].tolist() == [False, False, True, False]
    with pytest.raises(av.ScenarioError, match="not a module a file may name"):
        _choose_scenario("os.path:join").build()
    with pytest.raises(av.ScenarioError, match="fn cannot be called"):
        _choose_scenario("avblocks.scenarios.honeybee:entrance").build()


def test_the_distance_guard_is_the_disc_test():
    g = GENERATORS["guard"](input="pose", near=[[1.0, 2.0]], radius=0.5)
    pose = np.array([[1.3, 2.4, 0.0], [1.3, 2.41, 9.0], [1.0, 2.0, 1.0], [0.6, 2.0, 0.0]])
    # |(0.3, 0.4)| = 0.5 is on the circle (inside), 0.3^2 + 0.41^2 > 0.25 outside
    assert GENERATORS["guard"](input="pose", near=[1, 2], radius=0.5)(
        {"pose": pose}, np).tolist() == g({"pose": pose}, np).tolist() \
        == [True, False, True, True]
    for bad in ({"near": [1.0], "radius": 1.0}, {"near": [0, 0], "radius": -1.0},
                {"near": [0, 0]}):
        with pytest.raises(ValueError):
            GENERATORS["guard"](input="pose", **bad)


def test_arange_add_item():
    assert GENERATORS["arange"](n=3, start=12).tolist() == [12, 13, 14]
    assert GENERATORS["arange"](n=2).tolist() == [0, 1]
    s = GENERATORS["add"](a=500, b=12)
    assert s == 512 and isinstance(s, int)
    assert GENERATORS["add"](a=0.5, b=[1.0, 2.0]).tolist() == [1.5, 2.5]
    assert GENERATORS["item"](values=[1.0, 1.5], index=1) == 1.5
    assert GENERATORS["item"](values=[1.0, 1.5], index=-2) == 1.0
    with pytest.raises(av.AvError):
        GENERATORS["item"](values=[1.0, 1.5], index=2)
