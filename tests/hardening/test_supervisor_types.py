"""Supervisor / AgentModes definitions of the wrong type: a ParameterError
naming the argument, never AttributeError/TypeError from inside (issue 22)."""

import numpy as np
import pytest

from avblocks.controllers import AgentModes, Supervisor
from avblocks.core.errors import ParameterError

OK = dict(states=["a", "b"], transitions=[("a", "b")], initial="a")


@pytest.mark.parametrize("arg, value", [
    ("states", 5), ("states", "ab"), ("states", {"a": 1}), ("states", [1, 2]),
    ("states", [["a"], ["b"]]), ("states", None),
    ("transitions", 5), ("transitions", "ab"), ("transitions", [5]),
    ("transitions", [("a", ["b"])]), ("transitions", [({"a": 1}, "b")]),
    ("transitions", [("a", "b", 3)]), ("transitions", None),
    ("initial", ["a", ["b"]]), ("initial", {"a": 1}), ("initial", [["a"]]),
    ("initial", 3), ("initial", None),
    ("outputs", 5), ("outputs", ["a"]), ("outputs", {"y": 5}),
    ("outputs", {"y": {"a": "x", "b": "y"}}), ("outputs", {3: {"a": 1, "b": 2}}),
    ("outputs", {"y": {"a": {"k": 1}, "b": 2}}),
    ("inputs", 5), ("inputs", ["w"]), ("inputs", {"w": "abc"}), ("inputs", {"w": (-1,)}),
    ("inputs", {"w": {"k": 1}}), ("inputs", {"w": 2.5}), ("inputs", {5: ()}),
])
def test_wrong_types_name_the_argument(arg, value):
    with pytest.raises(ParameterError) as e:
        Supervisor(**{**OK, arg: value})
    assert e.value.param == arg, str(e.value)


@pytest.mark.parametrize("n", ["3", 2.5, None, 0, -1, [3], True])
def test_agent_modes_wrong_n(n):
    with pytest.raises(ParameterError) as e:
        AgentModes(n, **OK)
    assert e.value.param == "n"


def test_valid_definitions_still_build():
    s = Supervisor(**OK, inputs={"w": (), "v": 2, "z": ((3,), "float64")},
                   outputs={"y": {"a": 1.0, "b": 2.0}})
    np.testing.assert_array_equal(s.tables["y"], [1.0, 2.0])
    m = AgentModes(np.int64(4), **OK, inputs={"w": np.array([2])})
    assert m.n == 4
