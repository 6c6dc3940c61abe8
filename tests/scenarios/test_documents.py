"""Scenario files as editor documents: load, save back keeping the file's
form (comments, references, generator forms, anchors), atomic and confined
writes, conflicts; every built-in case study round-trips to the same run."""

import json
import os

import pytest
import yaml

import avblocks as av
from avblocks.cli import main
from avblocks.scenarios import builtin_scenarios, load_scenario
from avblocks.scenarios.document import (
    DocumentChanged,
    dump_yaml,
    load_document,
    revision_of,
    save_document,
)

YAML_BUILTINS = sorted(n for n, p in builtin_scenarios().items() if p.suffix == ".yaml")
PY_ONLY = sorted(n for n, p in builtin_scenarios().items() if p.suffix == ".py")
SMALL = ["--set", "t_final=1.5", "--set", "dt=0.05", "--set", "seed=3", "--quiet"]


def _run(target, out, *sets):
    assert main(["run", str(target), *SMALL, *sets, "--out", str(out)]) == 0
    return json.loads((out / "summary.json").read_text())


@pytest.mark.parametrize("name", YAML_BUILTINS)
def test_a_builtin_loaded_and_saved_untouched_is_the_same_file(name, tmp_path):
    got = load_document(name)
    assert got["builtin"] == name and got["path"] is None
    src = builtin_scenarios()[name]
    assert got["revision"] == revision_of(src.read_bytes())
    doc = got["document"]
    json.dumps(doc)                                   # plain JSON values
    assert doc == yaml.safe_load(src.read_text())     # the file's mapping, as parsed
    saved = save_document(f"{name}.yaml", doc, tmp_path, origin=name)
    assert saved == {"path": f"{name}.yaml", "draft": False,
                     "revision": revision_of(src.read_bytes())}
    assert (tmp_path / f"{name}.yaml").read_bytes() == src.read_bytes()


@pytest.mark.parametrize("name", YAML_BUILTINS)
def test_a_builtin_written_fresh_runs_to_the_same_summary(name, tmp_path, request):
    """No original to merge into: the document written by the fresh writer
    alone (other styles, no comments, anchors expanded) parses to the same
    mapping and runs to the same summary.json numbers as the built-in."""
    if name == "uav_tracking":
        request.getfixturevalue("mujoco_extra")
    doc = load_document(name)["document"]
    text = dump_yaml(doc)
    assert yaml.safe_load(text) == doc
    f = tmp_path / f"{name}.yaml"
    f.write_text(text)
    extra = (["--set", "followers=3"] if name == "formation" else
             ["--set", "agents=7"] if "agents" in doc["parameters"] else [])
    a = _run(name, tmp_path / "a", *extra)
    b = _run(f, tmp_path / "b", *extra)
    assert a["status"] == b["status"] == "complete"
    assert a["outcome"] == b["outcome"]
    assert a["numbers"] == b["numbers"] and a["agents"] == b["agents"]


def test_an_edited_document_keeps_the_untouched_lines(tmp_path):
    """formation: a gain changed, a block added, a wire removed (a draft:
    collision.pose is then unwired). Comments, $references, generator forms
    and the &n / *n anchors of the untouched lines stay as written."""
    name = "formation"
    original = builtin_scenarios()[name].read_text()
    doc = load_document(name)["document"]
    doc["blocks"]["drive"]["gain"] = 2.0
    doc["blocks"]["clock"] = {"type": "blocks.Clock"}
    doc["wires"].remove(["fleet.pose", "collision.pose"])
    doc["editor"] = {"layout": {"fleet": [40, 120], "drive": [320, 120]}}
    with pytest.raises(av.ScenarioError, match="collision"):     # not a draft: refused
        save_document("f.yaml", doc, tmp_path, origin=name)
    assert not (tmp_path / "f.yaml").exists()
    save_document("f.yaml", doc, tmp_path, draft=True, origin=name)
    text = (tmp_path / "f.yaml").read_text()
    assert yaml.safe_load(text) == doc                        # identical parse
    for line in original.splitlines():                        # untouched lines kept
        if "#" in line or "*n" in line or "&n" in line:
            if "collision.pose" in line:
                continue
            assert line in text.splitlines(), line
    assert "    gain: 2.0" in text and "  clock:\n    type: blocks.Clock" in text
    assert "[fleet.pose, collision.pose]" not in text
    assert text.rstrip().endswith("drive: [320, 120]")        # editor: the last key
    assert list(yaml.safe_load(text))[-1] == "editor"
    changed = [ln for ln in text.splitlines() if ln not in original.splitlines()]
    assert len(changed) <= 8, changed                          # only what was edited


def test_a_valid_edit_runs_with_the_new_value_and_a_revision_protects_it(tmp_path):
    src = builtin_scenarios()["waypoints"]
    (tmp_path / "w.yaml").write_bytes(src.read_bytes())
    got = load_document("w.yaml", root=tmp_path)
    assert got["path"] == "w.yaml" and got["builtin"] is None
    doc = got["document"]
    doc["blocks"]["drive"]["gain"] = 3.0
    saved = save_document("w.yaml", doc, tmp_path, revision=got["revision"])
    text = (tmp_path / "w.yaml").read_text()
    before, after = src.read_text().splitlines(), text.splitlines()
    assert len(before) == len(after)                 # one line changed, no other
    assert [(x, y) for x, y in zip(before, after) if x != y] == [
        ("    gain: 1.0", "    gain: 3.0")]
    assert saved["revision"] == revision_of((tmp_path / "w.yaml").read_bytes())
    sc = load_scenario(tmp_path / "w.yaml")
    d, _ = sc.with_overrides({"agents": 3}).build(output_dir=tmp_path / "o")
    assert float(d.blocks["drive"].block.gain[0]) == 3.0
    # someone else writes the file: the old revision is refused, nothing written
    (tmp_path / "w.yaml").write_text(text + "# edited elsewhere\n")
    with pytest.raises(DocumentChanged, match="changed on disk"):
        save_document("w.yaml", doc, tmp_path, revision=got["revision"])
    assert (tmp_path / "w.yaml").read_text().endswith("# edited elsewhere\n")


@pytest.mark.parametrize("path, match", [
    ("../out.yaml", "outside"),
    ("/tmp/elsewhere.yaml", "outside"),
    ("script.py", r"\.yaml or \.yml"),
    ("notes.txt", r"\.yaml or \.yml"),
])
def test_saving_is_confined_to_the_root_and_to_yaml(tmp_path, path, match):
    root = tmp_path / "root"
    root.mkdir()
    doc = load_document("waypoints")["document"]
    with pytest.raises(av.ScenarioError, match=match):
        save_document(path, doc, root)
    assert not any(root.iterdir())


def test_a_symbolic_link_out_of_the_root_is_refused(tmp_path):
    root = tmp_path / "root"
    root.mkdir()
    os.symlink(tmp_path, root / "up")
    doc = load_document("waypoints")["document"]
    with pytest.raises(av.ScenarioError, match="outside"):
        save_document("up/x.yaml", doc, root)
    with pytest.raises(av.ScenarioError, match="outside"):
        load_document("up/x.yaml", root=root)


def test_every_case_study_is_a_scenario_file():
    """Issue 31: the editor loads every built-in case study, so none is
    Python-only (each Python module is the twin of its file)."""
    assert PY_ONLY == []
    for name in builtin_scenarios():
        assert load_document(name)["document"]["blocks"], name


def test_a_python_module_is_not_a_document(tmp_path):
    """A Python scenario module named as a file is refused by name."""
    from avblocks.scenarios import pursuit
    with pytest.raises(av.ScenarioError) as e:
        load_document(pursuit.__file__)
    assert "pursuit.py" in str(e.value) and "is not a scenario file" in str(e.value)


def test_the_editor_section_is_layout_only(tmp_path):
    text = builtin_scenarios()["waypoints"].read_text()
    lay = text + ("editor:\n  layout: {fleet: [0, 0], drive: [300, 0]}\n"
                  "  groups: {team: {blocks: [fleet, drive], position: [10, 10]}}\n"
                  "  viewport: [0, 0, 1.5]\n")
    f = tmp_path / "w.yaml"
    f.write_text(lay)
    a = _run("waypoints", tmp_path / "a", "--set", "agents=4")
    b = _run(f, tmp_path / "b", "--set", "agents=4")
    assert a["numbers"] == b["numbers"] and a["outcome"] == b["outcome"]
    for bad, entry in [("editor: [1, 2]\n", "editor"),
                       ("editor: {layout: {fleet: [1]}}\n", "editor.layout.fleet"),
                       ("editor: {groups: {g: {blocks: fleet}}}\n", "editor.groups.g.blocks"),
                       ("editor: {viewport: [0, 0]}\n", "editor.viewport")]:
        f.write_text(text + bad)
        with pytest.raises(av.ScenarioError) as e:
            load_scenario(f)
        assert e.value.entry == entry


def test_an_invalid_draft_is_saved_and_loaded_back_as_it_is(tmp_path):
    doc = {"name": "draft", "parameters": {"agents": 3},
           "blocks": {"fleet": {"type": "vehicles.Unicycl", "pose0": "$agents"}},
           "wires": [["fleet.pose", "nowhere.u"]], "editor": {"layout": {"fleet": [1, 2]}}}
    with pytest.raises(av.ScenarioError, match="did you mean 'vehicles.Unicycle'"):
        save_document("d.yaml", doc, tmp_path)
    save_document("d.yaml", doc, tmp_path, draft=True)
    assert load_document("d.yaml", root=tmp_path)["document"] == doc
    (tmp_path / "list.yaml").write_text("- 1\n- 2\n")
    with pytest.raises(av.ScenarioError, match="mapping of sections"):
        load_document("list.yaml", root=tmp_path)


@pytest.mark.parametrize("edit, line", [
    # the entry that defines the anchor &n, and one that uses the alias *n
    (("fleet", "pose0", "formation_start"), "    pose0: {formation_start: {n: &n {team_size:"),
    (("lf", "leader", "formation_references"), "    leader: {formation_references: {n: *n,"),
])
def test_an_edit_next_to_an_anchor_or_alias_changes_that_entry_only(edit, line, tmp_path):
    original = builtin_scenarios()["formation"].read_text()
    doc = load_document("formation")["document"]
    node = doc["blocks"]
    for k in edit:
        node = node[k]
    node["spacing"] = 2.0
    text = dump_yaml(doc, original)
    assert yaml.safe_load(text) == doc
    new = [ln for ln in text.splitlines() if ln not in original.splitlines()]
    assert len(new) == 1 and new[0].startswith(line) and "spacing: 2.0" in new[0], new
    gone = [ln for ln in original.splitlines() if ln not in text.splitlines()]
    assert len(gone) == 2                          # the entry's two lines, now one
    assert text.count("&n") == 1 and text.count("*n") == original.count("*n")
