"""The editor opens drone_formation and uav_tracking (scenario files now)
with no errors, and their exported Python scripts, run, give the runs of
the files."""

from __future__ import annotations

import runpy

import numpy as np
import pytest

from avblocks.editor.service import EditorService


@pytest.mark.parametrize("name,t_final", [("drone_formation", 4.0),
                                          pytest.param("uav_tracking", 0.5,
                                                       marks=pytest.mark.mujoco)])
def test_loaded_checked_and_exported_script_runs_to_the_files_results(tmp_path, name,
                                                                        t_final, request):
    from avblocks.core.frontend import simulate
    from avblocks.scenarios.targets import load_any
    if name == "uav_tracking":
        request.getfixturevalue("mujoco_extra")
    service = EditorService(tmp_path)
    loaded = service.load(builtin=name)
    doc = loaded["document"]
    out = service.validate(doc)
    assert out["ok"] and not out["errors"], out["errors"]
    doc["parameters"]["t_final"] = t_final               # a short run of the same file
    text = service.export(doc, format="python")["text"]
    script = tmp_path / "exported.py"
    script.write_text(text)
    mine = runpy.run_path(str(script), run_name="__main__")["res"]
    d, sim = load_any(name, {"t_final": t_final})[:2]
    truth = simulate(d, progress=False, **sim)
    assert sorted(mine.keys()) == sorted(truth.keys())
    np.testing.assert_array_equal(mine.t, truth.t)
    for k in truth.keys():
        np.testing.assert_array_equal(mine[k], truth[k], err_msg=k)
