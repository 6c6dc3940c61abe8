"""Cases per student: ``--seed N`` and ``--student ID``.

Without a seed the checks use the fixed cases of the lab pages; with one
they draw their own (poses, gains, graphs), so the expected values a
student sees printed cannot be hard-coded. Asserted: the reference
solutions pass every seed tried; a solution that hard-codes the fixed
case's answer passes without a seed and fails with one; a wrong solution's
messages differ from seed to seed; seeds come from SHA-256 (computed here
independently) and are reported per file."""

from __future__ import annotations

import csv
import hashlib
import io
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from avblocks.cli import main
from avblocks.labs import Lab, get, run_checks
from avblocks.labs.remote import Submission, seed_for

from .mutations import write
from .test_labs import without_emulator

HERE = Path(__file__).resolve().parent
SOLUTIONS = HERE / "solutions"


def test_seed_for_is_sha256_of_its_parts():
    want = int.from_bytes(hashlib.sha256(b"avblocks lab\x1fstudent\x1fs123").digest()[:8],
                          "big") >> 1
    assert seed_for("avblocks lab", "student", "s123") == want


def test_the_cases_are_fixed_without_a_seed_and_drawn_with_one():
    fixed = Submission(None, {}, seed=None, check="ports")
    assert np.array_equal(fixed.rng(3).random(4), np.random.default_rng(3).random(4))
    draws = {(seed, check): Submission(None, {}, seed=seed, check=check).rng(3).random()
             for seed in (1, 2) for check in ("ports", "law")}
    assert len(set(draws.values())) == 4
    again = Submission(None, {}, seed=1, check="law").rng(3).random()
    assert again == draws[1, "law"]
    assert fixed.pick(1.5, lambda: 9.0) == 1.5
    assert Submission(None, {}, seed=1).pick(1.5, lambda: 9.0) == 9.0


@pytest.mark.parametrize("number,seed", [(n, s) for n in (1, 2, 3, 4, 5, 6, 7, 8)
                                         for s in (11, 12)])
def test_the_reference_solution_passes_every_seed(number, seed):
    lab = without_emulator(get(number)) if number in (6, 7) else get(number)
    r = run_checks(lab, SOLUTIONS / lab.template.name, seed=seed)
    assert r.passed, r.text()
    assert r.seed == seed


HARD_CODED = '''

def wheels_to_cmd(wheels, radius, track):
    """The answer of the lab page's fixed case, printed by the grader and copied."""
    import numpy as np
    return np.array({answer!r})
'''


def test_hard_coded_answers_pass_only_the_fixed_case(tmp_path):
    rng = np.random.default_rng(4)                # the fixed case of check_wheels
    w = rng.uniform(-10, 10, (7, 2))
    answer = np.column_stack([0.033 * (w[:, 1] + w[:, 0]) / 2,
                              0.033 * (w[:, 1] - w[:, 0]) / 0.16]).tolist()
    f = tmp_path / "copied.py"
    f.write_text((SOLUTIONS / "lab1_kinematics.py").read_text()
                 + HARD_CODED.format(answer=answer))
    name = "differential drive: wheels_to_cmd"
    fixed = {c.name: c for c in run_checks(get(1), f).checks}
    seeded = {c.name: c for c in run_checks(get(1), f, seed=7).checks}
    assert fixed[name].passed
    assert not seeded[name].passed and seeded[name].message.startswith(
        "port `cmd (wheels_to_cmd)` for radius"), seeded[name].message


def test_a_wrong_solution_sees_other_numbers_under_other_seeds(tmp_path):
    f = write(tmp_path, 1, "wrong_sign")
    msgs = []
    for seed in (None, 21, 22):
        r = run_checks(get(1), f, seed=seed)
        msgs.append({c.name: c.message for c in r.checks}["derivative (eq. 1)"])
    assert all(m.startswith("port `pose (its rate, derivative)`") for m in msgs)
    assert len(set(msgs)) == 3, msgs


@pytest.mark.parametrize("number,check,starts", [
    (7, "the reward, term by term", "port `reward (reward)`"),
    (8, "prediction: the unicycle model and body-frame noise", "port `cov (ekf_predict)`")])
def test_labs_7_and_8_draw_other_cases_under_other_seeds(tmp_path, number, check, starts):
    """A wrong solution (wrong_sign) of labs 7 and 8 fails the same check
    under every seed, with other numbers (N agents, weights, dt, q)."""
    lab = get(number)
    only = Lab(number, lab.name, lab.title, names=lab.names,
               checks=[c for c in lab.checks if c[0] == check])
    f = write(tmp_path, number, "wrong_sign")
    msgs = [run_checks(only, f, seed=seed).checks[0].message for seed in (None, 21, 22)]
    assert all(m.startswith(starts) for m in msgs), msgs
    assert len(set(msgs)) == 3, msgs


def test_student_ids_and_folder_seeds_are_reported(capsys, tmp_path):
    f = write(tmp_path, 1, "wrong_sign")
    assert main(["lab", "check", "1", str(f), "--student", "s123", "--json"]) == 1
    doc = json.loads(capsys.readouterr().out)
    assert doc["seed"] == seed_for("avblocks lab", "student", "s123")
    # the same id, the same cases
    assert main(["lab", "check", "1", str(f), "--seed", str(doc["seed"]), "--json"]) == 1
    again = json.loads(capsys.readouterr().out)
    assert again["checks"] == doc["checks"]
    folder = tmp_path / "class"
    folder.mkdir()
    for name in ("alice.py", "bob.py"):
        shutil.copyfile(SOLUTIONS / "lab1_kinematics.py", folder / name)
    assert main(["lab", "check", "1", str(folder), "--seed", "5", "--csv"]) == 0
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert [int(r["seed"]) for r in rows] == [seed_for("avblocks lab", 5, "alice.py"),
                                              seed_for("avblocks lab", 5, "bob.py")]
    with pytest.raises(SystemExit):                   # one of --seed, --student
        main(["lab", "check", "1", str(f), "--seed", "1", "--student", "x"])
    assert main(["lab", "check", "1", str(folder), "--student", "x"]) == 2
    assert "--student names one student" in capsys.readouterr().err
