"""A trained policy's file (``tasks.TaskCommand``'s ``policy``) named by a
scenario file lies under the file's folder; one the person running names
on the command line (``avblocks run ... --set controller=pi.npz``) is read
where they say, as ``--out`` is.

The shipped navigation file, copied to a folder of its own, is the
scenario; a policy inside the folder runs and drives the fleet exactly as
the Python module (``navigation.make_diagram(controller=path)``, a second
implementation) does with the same file.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import avblocks as av
from avblocks.cli import main
from avblocks.scenarios import builtin_scenarios, load_scenario

OBS_DIM = 4 + 12 + 6        # navigation's observation: goal, rays, others
SETS = {"t_final": 1.0, "seed": 3}


def _policy(path):
    """A linear policy, cmd = clip(2 * (goal relative to the agent))."""
    w = np.zeros((OBS_DIM, 2))
    w[0, 0] = w[1, 1] = 2.0
    path.parent.mkdir(parents=True, exist_ok=True)
    return av.controllers.Policy({"w0": w, "b0": np.zeros(2)}, output="clip").save(path)


def _file(folder, controller):
    """navigation.yaml in ``folder`` with ``controller`` as its default."""
    folder.mkdir(parents=True, exist_ok=True)
    text = builtin_scenarios()["navigation"].read_text()
    old = "  controller: scripted "
    assert text.count(old) == 1
    path = folder / "nav.yaml"
    path.write_text(text.replace(old, f"  controller: {json.dumps(str(controller))} "))
    return path


def _positions(d, sim):
    return np.asarray(av.simulate(d, progress=False, **sim)["fleet.position"])


def _module_run(policy):
    from avblocks.scenarios import navigation
    return _positions(*navigation.make_diagram(controller=str(policy), **SETS))


@pytest.mark.parametrize("name", ["../elsewhere/pi.npz", "ABS"])
def test_a_policy_the_file_names_outside_its_folder_is_refused(tmp_path, name):
    outside = _policy(tmp_path / "elsewhere" / "pi.npz")
    name = str(outside) if name == "ABS" else name
    sc = load_scenario(_file(tmp_path / "case", name)).with_overrides(SETS)
    with pytest.raises(av.ScenarioError) as e:
        sc.build(tmp_path / "out")
    msg = str(e.value)
    assert "nav.yaml" in msg and "blocks.command.policy" in msg, msg
    assert f"'{name}' is outside the folder" in msg, msg


def test_a_symlinked_policy_that_points_out_is_refused(tmp_path):
    outside = _policy(tmp_path / "elsewhere" / "pi.npz")
    path = _file(tmp_path / "case", "pi.npz")
    (tmp_path / "case" / "pi.npz").symlink_to(outside)
    with pytest.raises(av.ScenarioError, match="'pi.npz' is outside the folder"):
        load_scenario(path).with_overrides(SETS).build(tmp_path / "out")


def test_a_policy_inside_the_folder_runs_as_the_module_runs_it(tmp_path):
    inside = _policy(tmp_path / "case" / "policies" / "pi.npz")
    path = _file(tmp_path / "case", "policies/pi.npz")
    got = _positions(*load_scenario(path).with_overrides(SETS).build(tmp_path / "out"))
    np.testing.assert_array_equal(got, _module_run(inside))
    scripted = _positions(*load_scenario(path).with_overrides(
        {**SETS, "controller": "scripted"}).build(tmp_path / "out"))
    assert not np.allclose(got[-1], scripted[-1])       # the policy drove them


def test_values_from_a_file_are_confined_values_from_the_user_are_not(tmp_path):
    """Overrides from a file (a sweep's values) are the file's; the
    command line's (``user=True``, what ``avblocks run --set`` passes) are
    the user's. A value the file names stays confined even when the user
    sets something else."""
    outside = _policy(tmp_path / "elsewhere" / "pi.npz")
    sc = load_scenario(_file(tmp_path / "case", "scripted"))
    with pytest.raises(av.ScenarioError, match="outside the folder"):
        sc.with_overrides({**SETS, "controller": str(outside)}).build(tmp_path / "o1")
    d, sim = sc.with_overrides({**SETS, "controller": str(outside)}, user=True).build(
        tmp_path / "o2")
    np.testing.assert_array_equal(_positions(d, sim), _module_run(outside))
    bad = load_scenario(_file(tmp_path / "case2", outside))
    with pytest.raises(av.ScenarioError, match="outside the folder"):
        bad.with_overrides({**SETS, "agents": 3}, user=True).build(tmp_path / "o3")


def test_the_command_line_names_a_policy_anywhere(tmp_path, capsys):
    outside = _policy(tmp_path / "elsewhere" / "pi.npz")
    path = _file(tmp_path / "case", "scripted")
    argv = ["run", str(path), "--quiet", "--out", str(tmp_path / "out"),
            "--set", f"controller={outside}", "--set", "t_final=1", "--set", "seed=3"]
    assert main(argv) == 0
    s = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert s["status"] == "complete"
    # and a file naming the same policy is refused by the same command
    bad = _file(tmp_path / "case2", outside)
    assert main(["run", str(bad), "--quiet", "--out", str(tmp_path / "out2"),
                 "--set", "t_final=1"]) != 0
    err = capsys.readouterr().err
    assert "blocks.command.policy" in err and "outside the folder" in err, err
