"""Dunder names reached through a wiring entry or a port lookup (issue 22):
Python's protocols get a plain AttributeError, a wire or a ``port()`` call
naming one gets a WiringError / ScenarioError naming the port."""

import copy
import pickle  # noqa: F401  (protocol probing below)

import numpy as np
import pytest

import avblocks as av
from avblocks.core.errors import ScenarioError, WiringError
from avblocks.scenarios.targets import load_any

DUNDERS = ["__class__", "__dict__", "__deepcopy__", "__getstate__", "__init__", "__foo__"]


def _handle():
    d = av.Diagram()
    return d, d.add(av.blocks.Constant(np.ones((2, 2))), name="c")


@pytest.mark.parametrize("name", DUNDERS)
def test_port_lookup_of_a_dunder_is_a_wiring_error(name):
    _, h = _handle()
    with pytest.raises(WiringError) as e:
        h.port(name)
    assert e.value.port == name and "unknown port" in str(e.value)
    assert "['y']" in str(e.value)          # names the block's outputs


@pytest.mark.parametrize("name", [5, None, ("y",)])
def test_port_lookup_of_a_non_string(name):
    _, h = _handle()
    with pytest.raises(WiringError):
        h.port(name)


def test_python_protocols_see_plain_attribute_errors():
    _, h = _handle()
    assert not hasattr(h, "__deepcopy__") and not hasattr(h, "__foo__")
    assert getattr(h, "__array_interface__", "absent") == "absent"
    with pytest.raises(AttributeError) as e:
        h.__foo__  # noqa: B018
    assert not isinstance(e.value, av.AvError)
    assert type(h) is h.__class__          # the real attribute is untouched
    assert copy.copy(h).name == "c"
    assert h.port("y").path == "c.y" and h.y.path == "c.y"


@pytest.mark.parametrize("name", DUNDERS)
def test_scenario_wire_naming_a_dunder(tmp_path, name):
    p = tmp_path / "w.yaml"
    p.write_text(f"""
blocks:
  fleet: {{type: vehicles.Unicycle, pose0: [[0, 0, 0]]}}
  drive: {{type: controllers.PointToPoint, waypoints: [[[1, 1]]]}}
wires:
  - [fleet.{name}, drive.pose]
  - [drive.cmd, fleet.cmd]
""")
    with pytest.raises(ScenarioError) as e:
        load_any(str(p), {})
    assert e.value.entry == "wires[0]" and name in str(e.value)
