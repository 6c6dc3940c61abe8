"""The editor's validation (:mod:`avblocks.editor.validation`) says what the
library says, on the field that caused it.

Independent truth: the library's own error for the same value, raised by
constructing the block (or calling the engine's argument checks) directly in
the test, not through the editor; and the scenario file the page would save,
read by the loader. Each case is one of issue 44's: ``gain = [1, 2, 3, 4,
5]``, ``.nan``, ``1e999``, ``n = -3``, ``agents = 0``, the ``agents`` field's
own error, a wired input never blamed for its driver's parameter, ``t_final =
abc``."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest

import avblocks as av
from avblocks.core.errors import AvError
from avblocks.editor.service import EditorService


@pytest.fixture(scope="module")
def svc(tmp_path_factory):
    s = EditorService(tmp_path_factory.mktemp("v"))
    yield s
    s.close()


@pytest.fixture(scope="module")
def base(svc):
    return svc.load(builtin="waypoints")["document"]


def errors(svc, base, change):
    d = copy.deepcopy(base)
    change(d)
    v = svc.validate(d)
    assert not v["ok"]
    return v["errors"]


def library_error(fn):
    with pytest.raises(AvError) as e:
        fn()
    return str(e.value)


WPS = np.zeros((15, 3, 2))          # what random_waypoints gives 15 agents


def drive(**kw):
    return av.controllers.PointToPoint(WPS, **kw)


@pytest.mark.parametrize("value", [[1, 2, 3, 4, 5], math.nan, math.inf])
def test_a_bad_gain_is_the_library_error_on_the_gain_field(svc, base, value):
    errs = errors(svc, base, lambda d: d["blocks"]["drive"].__setitem__("gain", value))
    # exactly one error: on the field, in the library's words; the wired
    # fleet.cmd (driven by drive.cmd) is not "not connected"
    (e,) = errs
    assert (e["block"], e["param"], e["field"], e["port"]) == \
        ("drive", "gain", "blocks.drive.gain", None)
    assert e["message"] == library_error(lambda: drive(gain=value))
    assert "not connected" not in str(errs)


def test_a_gain_per_agent_builds(svc, base):
    d = copy.deepcopy(base)
    d["blocks"]["drive"]["gain"] = [1.0] * 15
    assert svc.validate(d)["ok"]
    drive(gain=[1.0] * 15)                   # the library takes it too


def test_n_negative_is_blamed_on_n_not_on_the_waypoints(svc, base):
    (e,) = errors(svc, base, lambda d: d["blocks"]["drive"].__setitem__("n", -3))
    assert (e["field"], e["param"]) == ("blocks.drive.n", "n")
    assert e["message"] == library_error(lambda: drive(n=-3))
    assert "out of range" in e["message"] and "waypoints" not in e["message"]


def test_agents_zero_in_words_and_on_the_agents_field(svc, base):
    errs = errors(svc, base, lambda d: d["parameters"].__setitem__("agents", 0))
    text = " ".join(e["message"] for e in errs)
    assert "zero-size" not in text and "reduction" not in text and "ValueError" not in text
    own = [e for e in errs if e["field"] == "parameters.agents"]
    assert [e["message"] for e in own] == \
        ["'agents' is an agent count: out of range (expected >= 1, found 0)"]
    by_field = {e["field"]: e["message"] for e in errs}
    # the blocks that use it: the library's own words for an empty fleet
    assert by_field["blocks.fleet.pose0"] == library_error(
        lambda: av.vehicles.Unicycle(pose0=np.zeros((0, 3))))
    assert by_field["blocks.drive.waypoints"] == library_error(
        lambda: av.controllers.PointToPoint(np.zeros((0, 3, 2))))
    assert "is empty" in by_field["blocks.drive.waypoints"]


@pytest.mark.parametrize("value", ["abc", 2.5, -2])
def test_the_agents_field_shows_its_own_error(svc, base, value):
    errs = errors(svc, base, lambda d: d["parameters"].__setitem__("agents", value))
    own = [e for e in errs if e["field"] == "parameters.agents"]
    assert len(own) == 1 and own[0]["param"] == "agents"
    from avblocks.core.params import integer
    words = library_error(lambda: integer(value, None, "agents", lo=1))
    assert own[0]["message"] == words.replace("in parameter 'agents': ",
                                              "'agents' is an agent count: ")
    # a generator that failed on its n: $agents is agents's error too
    gen = [e for e in errs if e["field"] == "blocks.fleet.pose0"]
    assert gen and gen[0]["refs"] == ["agents"]


def test_a_reference_carries_the_error_to_its_parameter(svc, base):
    (e,) = errors(svc, base, lambda d: d["parameters"].__setitem__("speed", -1.0))
    assert e["field"] == "blocks.drive.v_max" and e["refs"] == ["speed"]
    assert e["message"] == library_error(lambda: drive(v_max=-1.0))


@pytest.mark.parametrize("setting,value", [("t_final", "abc"), ("dt", -1),
                                           ("t_final", 3.333), ("solver", "fast")])
def test_run_settings_checked_as_the_engine_checks_them(svc, base, setting, value):
    (e,) = errors(svc, base, lambda d: d["simulation"].__setitem__(setting, value))
    assert e["field"] == f"simulation.{setting}" and e["param"] == setting
    sim = {"t_final": 60.0, "dt": 0.01, "solver": "rk4", setting: value}
    d = av.Diagram()
    d.add(av.blocks.Constant(1.0), name="c")
    # the NumPy engine refuses the same settings with the same words
    assert e["message"] == library_error(
        lambda: av.simulate(d, sim["t_final"], dt=sim["dt"], solver=sim["solver"],
                            progress=False))


def test_an_outcome_naming_an_unlogged_signal_is_a_problem_before_run(svc, base):
    (e,) = errors(svc, base, lambda d: d["simulation"].__setitem__("log", ["fleet.pose"]))
    assert e["field"] == "outcome" and "drive.done" in e["message"]


def test_save_says_draft_only_for_drafts(svc, base):
    saved = svc.save("ok.yaml", copy.deepcopy(base), draft=True)
    assert saved["draft"] is False           # valid: avblocks run takes it
    bad = copy.deepcopy(base)
    bad["blocks"]["drive"]["gain"] = -1
    saved = svc.save("bad.yaml", bad, draft=True)
    assert saved["draft"] is True
    with pytest.raises(av.ScenarioError):    # and avblocks run refuses it
        av.scenarios.load_scenario(str(svc.root / "bad.yaml")).build(svc.root / "out")


@pytest.mark.parametrize("key", ["name", "parameters", "blocks", "wires", "simulation",
                                 "editor"])
@pytest.mark.parametrize("value", [True, 5, "x", [1], None, 1.5, [[1, 2]],
                                   {"x": {"type": 3}}])
def test_any_value_at_a_top_level_key_is_an_editor_error_never_internal(svc, base, key,
                                                                        value):
    """The fuzz found ``parameters: true`` ending export in a TypeError (a 500):
    every top-level key holding a value of the wrong kind gets the editor's own
    error (or validates, where the value is allowed), from validate and export."""
    from avblocks.editor.errors import EditorError
    d = copy.deepcopy(base)
    d[key] = value
    for call in (lambda: svc.validate(d), lambda: svc.export(document=d)):
        try:
            assert isinstance(call(), dict)
        except EditorError as e:
            assert e.kind != "InternalError" and e.status == 400, e
