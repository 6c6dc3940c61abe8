"""uav_tracking.yaml is the case study: the file (its MuJoCo scene given
by numbers) runs to the summary the Python module gave before the file
existed; the same scene exported to MJCF and named by the file gives the
same run as the Python twin, image for image; a bad MJCF entry is an error
naming the file and the entry."""

from __future__ import annotations

import json

import numpy as np
import pytest

import avblocks as av

from ._mj import need

pytestmark = pytest.mark.mujoco

#: ``avblocks run uav_tracking --set t_final=3`` on main before the file
#: existed (commit cf15bf0, the Python module): the independent truth.
MAIN_T3 = {"max_error_m": 0.9091820458588035, "rms_error_m": 0.519889814604812,
           "found_fraction": 1.0, "in_view_fraction": 1.0}


@pytest.fixture(scope="module")
def ut():
    need("mujoco")
    need("cv2")
    from avblocks.scenarios import uav_tracking
    return uav_tracking


def test_the_file_runs_to_mains_summary(ut, tmp_path):
    from avblocks.cli import main
    from avblocks.scenarios import builtin_scenarios
    assert builtin_scenarios()["uav_tracking"].suffix == ".yaml"
    out = tmp_path / "out"
    assert main(["run", "uav_tracking", "--set", "t_final=3", "--quiet",
                 "--out", str(out)]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["status"] == "complete" and s["simulated_s"] == 3.0
    assert s["numbers"] == MAIN_T3
    assert (out / "tracking_error.png").is_file()


def _file_with_mjcf(ut, folder):
    """The shipped file with its scene replaced by an MJCF file in ``folder``:
    the Python twin's scene, exported (Scene.to_mjcf)."""
    from avblocks.scenarios import builtin_scenarios
    scene, _mount = ut.build_scene(4.0, 160, 120, 60.0, np.array([-0.6, 0.4, 4.0]),
                                   np.zeros(3), True, (320, 240))
    (folder / "street.xml").write_text(scene.to_mjcf())
    text = builtin_scenarios()["uav_tracking"].read_text()
    a, b = text.index("    scene: &scene"), text.index("    period: $dt")
    text = (text[:a] + "    scene: &scene {mujoco_scene: {mjcf: street.xml, ground_robots: "
            "{target: [target0]}, quadrotors: {uav: [uav0]}}}\n" + text[b:])
    path = folder / "mine.yaml"
    path.write_text(text)
    return path


def test_a_scene_from_an_mjcf_file_gives_the_twins_run(ut, tmp_path):
    from avblocks.scenarios import load_scenario
    sets = {"t_final": 1.5}
    d1, s1 = ut.make_diagram(**sets)
    r1 = av.simulate(d1, progress=False, **s1)
    sc = load_scenario(_file_with_mjcf(ut, tmp_path)).with_overrides(sets)
    d2, s2 = sc.build(tmp_path / "out")
    scene = d2["uav"].block.scene
    assert scene.camera_names() == ["uav0_cam", "overview"]      # mount and fixed camera
    r2 = av.simulate(d2, progress=False, **s2)
    assert len(r2.t) == 16
    for k in r2.keys():
        np.testing.assert_array_equal(np.asarray(r2[k]), np.asarray(r1[k]), err_msg=k)
    assert ut.outcome(r2)[1] == ut.outcome(r1)[1]


@pytest.mark.parametrize("scene, entry, words", [
    ({"mjcf": "nowhere.xml", "quadrotors": {"uav": ["uav0"]}}, "mujoco_scene.mjcf",
     "not a file"),
    ({"mjcf": "../outside.xml"}, "mujoco_scene.mjcf", "outside the folder"),
    ({"mjcf": "bad.xml"}, "mujoco_scene.mjcf", "bad.xml"),
    ({"mjcf": "ok.xml", "quadrotors": {"uav": ["nobody"]}}, "mujoco_scene.mjcf",
     "no such body"),
    ({"mjcf": "ok.xml", "world": {}}, "mujoco_scene", "cannot be given"),
    ({"mjcf": "ok.xml", "quadrotors": {"uav": "uav0"}}, "mujoco_scene.quadrotors.uav",
     "list of body names"),
    ({"ground_robots": {"t": {"radius": 1.0}}}, "mujoco_scene.ground_robots.t", "pose0"),
    ({"quadrotors": {"u": {"position0": [[0, 0, 1]], "camera": {"fov": 3}}}},
     "mujoco_scene.quadrotors.u.camera", "fov"),
    ({"scenery": 1}, "mujoco_scene", "scenery"),
])
def test_a_bad_scene_names_the_file_and_the_entry(ut, tmp_path, scene, entry, words):
    from avblocks.scenarios import Scenario
    folder = tmp_path / "case"
    folder.mkdir()
    (folder / "bad.xml").write_text("<mujoco><worldbody><body></mujoco>")
    (folder / "ok.xml").write_text(
        '<mujoco><worldbody><body name="uav0" pos="0 0 1"><freejoint/>'
        '<geom type="sphere" size="0.1"/></body></worldbody></mujoco>')
    sc = Scenario({"name": "s", "blocks": {"world": {
        "type": "interfaces.mujoco.PhysicsWorld", "scene": {"mujoco_scene": scene}}}},
        str(folder / "s.yaml"))
    with pytest.raises(av.ScenarioError) as e:
        sc.build(tmp_path / "out")
    msg = str(e.value)
    assert "s.yaml" in msg and f"blocks.world.scene.{entry}" in msg and words in msg, msg
