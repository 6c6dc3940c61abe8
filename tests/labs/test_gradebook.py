"""For the gradebook: Gradescope's ``results.json``, points per student in a
folder's CSV, an instructor's ``--extra-checks`` with point weights.

The ``results.json`` files are validated against a JSON Schema written
from Gradescope's published autograder specification
(``gradescope_results.schema.json``, with the ``jsonschema`` package);
the schema itself is first checked against the specification's own
example, so that it accepts what Gradescope documents."""

from __future__ import annotations

import csv
import io
import json
import shutil
from pathlib import Path

import jsonschema
import pytest

from avblocks.cli import main
from avblocks.labs import get

from .mutations import source

HERE = Path(__file__).resolve().parent
SOLUTION = HERE / "solutions" / "lab1_kinematics.py"
SCHEMA = json.loads((HERE / "gradescope_results.schema.json").read_text())

#: the example of Gradescope's specification ("Output format"), its comments removed
SPEC_EXAMPLE = {
    "score": 44.0, "execution_time": 136, "output": "Text relevant to the entire submission",
    "output_format": "simple_format", "test_output_format": "text",
    "test_name_format": "text", "visibility": "after_due_date", "stdout_visibility": "visible",
    "extra_data": {},
    "tests": [{"score": 2.0, "max_score": 2.0, "status": "passed", "name": "Your name here",
               "name_format": "text", "number": "1.1",
               "output": "Giant multiline string that will be placed in a <pre> tag and "
                         "collapsed by default",
               "output_format": "text", "tags": ["tag1", "tag2", "tag3"],
               "visibility": "visible", "extra_data": {}}],
    "leaderboard": [{"name": "Accuracy", "value": .926},
                    {"name": "Time", "value": 15.1, "order": "asc"},
                    {"name": "Stars", "value": "*****"}]}

EXTRA = '''
import numpy as np
from avblocks.labs import Check
from avblocks.labs.grading import compare

LAB = 1


def standing_still(sub):
    cmd = sub.wheels_to_cmd(np.zeros((3, 2)), 0.05, 0.2)
    compare("cmd (wheels_to_cmd)", np.zeros((3, 2)), cmd, atol=0.0, case=" with wheels still")
    return "no motion without wheel speed"


def spin_in_place(sub):
    w = np.array([[-2.0, 2.0]])
    cmd = sub.wheels_to_cmd(w, 0.05, 0.2)
    compare("cmd (wheels_to_cmd)", [[0.0, 1.0]], cmd, atol=1e-12, case=" spinning in place")
    return "turns on the spot"


CHECKS = [Check("hidden: wheels still", standing_still, points=2.5,
                visibility="after_published"),
          ("hidden: spin in place", spin_in_place, 1.5)]
'''


def _validator():
    cls = jsonschema.validators.validator_for(SCHEMA)
    cls.check_schema(SCHEMA)
    return cls(SCHEMA)


def test_the_schema_accepts_the_specifications_example_and_refuses_typos():
    v = _validator()
    v.validate(SPEC_EXAMPLE)
    for bad in ({"tests": [{"name": "no score anywhere"}]},
                {"score": 1, "tests": [{"score": 1, "visiblity": "visible"}]},
                {"score": 1, "visibility": "later"},
                {"score": "1"}):
        assert list(v.iter_errors(bad)), bad


def _gradescope(capsys, tmp_path, f, *extra):
    out = tmp_path / "results.json"
    rc = main(["lab", "check", "1", str(f), "--gradescope", str(out), *extra])
    capsys.readouterr()
    doc = json.loads(out.read_text())
    _validator().validate(doc)
    return rc, doc


@pytest.mark.parametrize("kind,rc_want,score", [("reference", 0, 5.0), ("wrong_sign", 1, 2.0),
                                                ("binary", 1, 0.0)])
def test_results_json_follows_the_specification(capsys, tmp_path, kind, rc_want, score):
    f = tmp_path / "lab1_kinematics.py"
    if kind == "reference":
        shutil.copyfile(SOLUTION, f)
    elif kind == "binary":
        f.write_bytes(b"\x00\x01binary")
    else:
        f.write_text(source(1, kind))
    rc, doc = _gradescope(capsys, tmp_path, f)
    names = [name for name, _ in get(1).checks]
    assert rc == rc_want
    assert [t["name"] for t in doc["tests"]] == names
    assert [t["max_score"] for t in doc["tests"]] == [1.0] * 5
    assert doc["score"] == score == sum(t["score"] for t in doc["tests"])
    assert all((t["status"] == "passed") == (t["score"] == t["max_score"]) for t in doc["tests"])
    assert doc["output"].startswith(f"lab 1: {int(score)} of 5 checks passed, {score:g} of 5 "
                                    f"points")
    if kind == "binary":
        assert "load: the file is not Python source text" in doc["output"]
        assert {t["output"] for t in doc["tests"]} == {"not run: the file did not load"}


def test_extra_checks_with_points_in_the_csv_and_results_json(capsys, tmp_path):
    extra = tmp_path / "extra"
    extra.mkdir()
    (extra / "more.py").write_text(EXTRA)
    (extra / "for_lab2.py").write_text("LAB = 2\nCHECKS = []\n")     # another lab's: skipped
    (extra / "_helpers.py").write_text("raise RuntimeError('not a check module')\n")
    folder = tmp_path / "class"
    folder.mkdir()
    shutil.copyfile(SOLUTION, folder / "alice.py")
    # spins the wrong way: the lab's checks catch the sign, so do the hidden ones
    (folder / "bob.py").write_text(source(1, "wrong_sign").replace(
        "radius * (wr - wl) / track]", "radius * (wl - wr) / track]"))
    rc = main(["lab", "check", "1", str(folder), "--csv", "--extra-checks", str(extra)])
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert rc == 1
    assert [(r["file"], r["points"], r["max_points"], r["checks_passed"], r["checks_total"])
            for r in rows] == [("alice.py", "9", "9", "7", "7"),
                               ("bob.py", "3.5", "9", "2", "7")]
    assert "hidden: spin in place: port `cmd (wheels_to_cmd)` spinning in place" in \
        rows[1]["failed"]
    rc, doc = _gradescope(capsys, tmp_path, folder / "alice.py", "--extra-checks", str(extra))
    hidden = doc["tests"][-2:]
    assert [(t["name"], t["max_score"], t["visibility"]) for t in hidden] == [
        ("hidden: wheels still", 2.5, "after_published"), ("hidden: spin in place", 1.5,
                                                            "visible")]
    assert doc["score"] == 9.0
    # what a student sees at once does not count the check shown after publication
    assert doc["output"].startswith("lab 1: 6 of 6 checks passed, 6.5 of 6.5 points (and 1 "
                                    "more check shown later)")


@pytest.mark.parametrize("body,says", [
    ("LAB = 1\n", "a check module must define CHECKS"),
    ("LAB = 'one'\nCHECKS = []\n", "LAB must be a lab's number"),
    ("LAB = 1\nCHECKS = [('ports', lambda sub: 'x')]\n", "check 'ports' is named twice"),
    ("LAB = 1\nCHECKS = [('free', lambda sub: 'x', -1)]\n", "points must be a finite number > 0"),
    ("LAB = 1\nimport nothing_here\n", "the check module failed to load: ModuleNotFoundError"),
    # a student's file (no LAB): refused before anything of the folder runs
    ("import os\nopen(os.path.join(os.path.dirname(__file__), 'ran'), 'w')\n",
     "not a check module: it assigns no LAB (or LABS) at its top level"),
    ("LAB = 1\ndef (:\n", "the check module does not parse (SyntaxError"),
])
def test_a_bad_extra_check_module_is_status_2(capsys, tmp_path, body, says):
    (tmp_path / "bad.py").write_text(body)
    (tmp_path / "a_checks.py").write_text("LAB = 1\nopen(__file__ + '.ran', 'w')\n"
                                          "CHECKS = [('probe', lambda sub: 'x')]\n")
    rc = main(["lab", "check", "1", str(SOLUTION), "--extra-checks", str(tmp_path)])
    err = capsys.readouterr().err
    assert rc == 2 and says in err and "bad.py" in err, err
    assert not (tmp_path / "ran").exists()
    # a file that is not a check module stops the run before any of the folder runs
    assert (tmp_path / "a_checks.py.ran").exists() != ("not a check module" in says
                                                     or "does not parse" in says)


def test_gradescope_wants_one_file(capsys, tmp_path):
    shutil.copyfile(SOLUTION, tmp_path / "a.py")
    assert main(["lab", "check", "1", str(tmp_path), "--gradescope",
                 str(tmp_path / "r.json")]) == 2
    assert "--gradescope writes the results of one submission" in capsys.readouterr().err


def test_the_docs_list_the_csv_columns_the_grader_writes():
    """docs/labs/index.md's table of CSV columns is the grader's own
    (``report.CSV_COLUMNS`` and what each holds)."""
    from avblocks.labs.report import CSV_COLUMNS, CSV_HELP
    page = (HERE.parents[1] / "docs" / "labs" / "index.md").read_text()
    table = page.split("<!-- csv-columns -->")[1].split("<!-- /csv-columns -->")[0]
    rows = [ln.split("|")[1:3] for ln in table.strip().splitlines()[2:]]
    assert [(a.strip().strip("`"), b.strip()) for a, b in rows] == \
        [(c, CSV_HELP[c]) for c in CSV_COLUMNS]
