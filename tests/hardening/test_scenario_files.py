"""Scenario files are data: they write only inside the output folder, read
only under their own folder, and every malformed file gets one clear line."""

import json
import os
import time

import numpy as np
import pytest

import avblocks as av
from avblocks.cli import main
from avblocks.core.errors import ScenarioError
from avblocks.scenarios import load_scenario

BASE = """
name: tiny
parameters: {n: 2}
blocks:
  fleet: {type: vehicles.Unicycle, pose0: {zeros: {shape: [$n, 3]}}}
  c: {type: blocks.Constant, value: {tile: {value: [1.0, 0.0], n: $n}}}
wires:
  - [c.y, fleet.cmd]
simulation: {t_final: 0.5, dt: 0.1}
"""

SCOPE = BASE.replace("wires:", "  scope: {type: viz.Scope, inputs: [u], path: PATH}\nwires:\n"
                     "  - [fleet.pose, scope.u]")
ANIM = BASE.replace("wires:", "  anim: {type: viz.Animation2D, n: 2, movie: PATH}\nwires:\n"
                    "  - [fleet.pose, anim.pose]")


def write(folder, text, name="s.yaml", mode="w"):
    p = folder / name
    if isinstance(text, bytes):
        p.write_bytes(text)
    else:
        p.write_text(text)
    return p


def run(args, capsys):
    rc = main(["run", *args, "--quiet"])
    cap = capsys.readouterr()
    return rc, cap.out, cap.err


# ------------------------------------------------------------------ security
@pytest.mark.parametrize("template", [SCOPE, ANIM], ids=["Scope.path", "Animation2D.movie"])
@pytest.mark.parametrize("target", ["abs", "dotdot", "symlink"])
def test_scenario_cannot_write_outside_the_output_folder(tmp_path, capsys, template,
                                                         target):
    victim = tmp_path / "victim.png" if template is SCOPE else tmp_path / "victim.gif"
    victim.write_bytes(b"precious")
    out = tmp_path / "out"
    out.mkdir()
    if target == "abs":
        path = str(victim)
    elif target == "dotdot":
        path = "../" + victim.name
    else:
        (out / "link").symlink_to(tmp_path)
        path = "link/" + victim.name
    scen = write(tmp_path, template.replace("PATH", path))
    rc, _out, err = run([str(scen), "--out", str(out)], capsys)
    assert rc == 2
    assert "outside the folder" in err and str(scen) in err
    assert victim.read_bytes() == b"precious"
    assert not (out / "results.nc").exists()     # refused before simulating


def test_scenario_writes_relative_names_inside_the_output_folder(tmp_path, capsys):
    scen = write(tmp_path, SCOPE.replace("PATH", "scope.png"))
    out = tmp_path / "out"
    rc, _o, err = run([str(scen), "--out", str(out)], capsys)
    assert rc == 0, err
    assert (out / "scope.png").read_bytes()[:4] == b"\x89PNG"
    assert not (tmp_path / "scope.png").exists()


def test_scenario_name_cannot_place_the_default_output_folder(tmp_path, capsys,
                                                              monkeypatch):
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    for name in ("../../escaped", "/tmp/abs-escape", "..", "a/../../b"):
        scen = write(work, BASE.replace("name: tiny", f"name: {json.dumps(name)}"))
        rc, _o, err = run([str(scen)], capsys)
        assert rc == 0, err
    made = [p for p in tmp_path.rglob("results.nc")]
    assert made and all((work / "avblocks-out") in p.parents for p in made)
    assert len({p.parent for p in made}) == 4
    assert not os.path.exists("/tmp/abs-escape/results.nc")


def test_movie_background_must_lie_under_the_scenario_folder(tmp_path):
    from PIL import Image
    secret = tmp_path / "secret.png"
    Image.fromarray(np.zeros((4, 4, 3), np.uint8)).save(secret)
    sub = tmp_path / "scen"
    sub.mkdir()
    for bad in (str(secret), "../secret.png", "/etc/passwd"):
        sc = load_scenario(write(sub, BASE + f"movie: {{background: {json.dumps(bad)}}}\n"))
        with pytest.raises(ScenarioError, match="outside the folder"):
            sc.movie_options()
    Image.fromarray(np.zeros((4, 4, 3), np.uint8)).save(sub / "bg.png")
    sc = load_scenario(write(sub, BASE + "movie: {background: bg.png}\n"))
    assert sc.movie_options()["background"] == (sub / "bg.png").resolve()


def test_world_files_must_lie_under_the_scenario_folder(tmp_path):
    from PIL import Image
    img = np.full((20, 20), 255, np.uint8)
    img[5:10, 5:10] = 0
    Image.fromarray(img).save(tmp_path / "map.png")
    sub = tmp_path / "scen"
    sub.mkdir()
    Image.fromarray(img).save(sub / "map.png")
    col = BASE.replace("wires:", "  col: {type: environment.Collision, n: 2, world: WORLD}"
                       "\nwires:\n  - [fleet.pose, col.pose]")
    for bad in ("{world: {image: {path: ../map.png, resolution: 1.0}}}",
                "{world: {geojson: /etc/passwd}}"):
        sc = load_scenario(write(sub, col.replace("WORLD", bad)))
        with pytest.raises(ScenarioError, match="outside the folder"):
            sc.build()
    sc = load_scenario(write(sub, col.replace(
        "WORLD", "{world: {image: {path: map.png, resolution: 1.0}}}")))
    d, _ = sc.build()
    w = d.build().blocks[d.build().names.index("col")].world
    # dark pixels (rows 5..9 from the top of a 20-row map) are occupied
    assert not w.is_free(np.array([[7.5, 12.5]]))[0]
    assert w.is_free(np.array([[15.5, 2.5]]))[0]


# ---------------------------------------------------------------- robustness
def test_world_values_build_a_world(tmp_path):
    col = BASE.replace("wires:", """  col:
    type: environment.Collision
    n: 2
    world:
      world:
        bounds: [-10, -10, 10, 10]
        obstacles:
          - [[0.3, -1], [4, -1], [4, 1], [0.3, 1]]
          - {circle: {center: [-5, 0], radius: 1.5}}
wires:
  - [fleet.pose, col.pose]""")
    d, sim = load_scenario(write(tmp_path, col)).build()
    c = d.build()
    w = c.blocks[c.names.index("col")].world
    free = w.is_free(np.array([[3.0, 0.0], [-5.0, 1.4], [-5.0, 1.6], [0.0, 0.0]]))
    assert free.tolist() == [False, False, True, True]
    res = av.simulate(d, log=["col.hit_obstacle"], **sim)
    # both start at the origin and drive along +x at 1 m/s with a 0.2 m disc:
    # they touch the square (x >= 0.3) from x = 0.1 on
    hit = res["col.hit_obstacle"]
    assert not hit[0].any() and hit[res.t >= 0.15].all()


@pytest.mark.parametrize("text,match", [
    (b"name: x\nblocks: {a: \xff\xfe}\n", "not UTF-8"),
    (BASE.replace("vehicles.Unicycle", "[vehicles.Unicycle]"), "must be a block type"),
    (BASE.replace("vehicles.Unicycle", "{a: 1}"), "must be a block type"),
    (BASE + "name: again\n", "duplicate key 'name'"),
    (BASE.replace("n: $n}}}", "n: $n}}, type: blocks.Constant}"), "duplicate key 'type'"),
    ("name: x\nblocks: [unclosed\n", r"cannot parse: .* at line \d+, column \d+"),
    ("a: &x [*x]\n", "cannot parse|recursive"),
    (BASE.replace("{shape: [$n, 3]}", "{shape: [-2, 3]}"), "out of range"),
    (BASE.replace("n: $n}}", "n: -1}}"), "out of range"),
    (BASE.replace("n: $n}}", "n: 2.5}}"), "whole number"),
    (BASE.replace("{shape: [$n, 3]}", "{shape: [1.0e+30, 3]}"), "out of range"),
    (BASE.replace("blocks:", "blocks:\n  w: {type: environment.Collision, n: 2, "
                  "world: {world: {obstacles: 3}}}"), "obstacles must be a list"),
    (BASE.replace("blocks:", "blocks:\n  w: {type: environment.Collision, n: 2, "
                  "world: {world: {obstacles: [{square: 1}]}}}"), "an obstacle is"),
])
def test_malformed_files_get_one_clear_line(tmp_path, text, match):
    p = write(tmp_path, text)
    with pytest.raises(ScenarioError, match=match) as ei:
        load_scenario(p).build()
    assert "\n" not in str(ei.value) and str(p) in str(ei.value)


def test_alias_bomb_is_refused_fast(tmp_path):
    lines = ["a0: &a0 [x, x, x, x, x, x, x, x, x, x]"]
    for i in range(1, 11):
        prev = f"*a{i - 1}"
        lines.append(f"a{i}: &a{i} [{', '.join([prev] * 10)}]")
    text = "\n".join(lines) + "\nname: bomb\n"
    assert len(text) < 1500          # 10^11 leaves once expanded
    p = write(tmp_path, text)
    t0 = time.perf_counter()
    with pytest.raises(ScenarioError, match="expand to more than"):
        load_scenario(p)
    assert time.perf_counter() - t0 < 5.0


def test_aliases_within_the_bound_still_work(tmp_path):
    text = BASE.replace("parameters: {n: 2}", "parameters: {n: 2}\nmovie: &m {trail: 1.0}")
    sc = load_scenario(write(tmp_path, text))
    assert sc.movie_options() == {"trail": 1.0}


def test_folder_is_not_a_file_and_never_shadows_a_builtin(tmp_path, capsys, monkeypatch):
    (tmp_path / "folder.yaml").mkdir()
    with pytest.raises(ScenarioError, match="is a folder"):
        load_scenario(tmp_path / "folder.yaml")
    monkeypatch.chdir(tmp_path)
    (tmp_path / "waypoints").mkdir()
    rc, out, err = run(["waypoints", "--set", "agents=2", "--set", "simulation.t_final=0.2",
                        "--out", str(tmp_path / "o")], capsys)
    assert rc == 0, err
    assert av.Results.load(tmp_path / "o" / "results.nc")["fleet.pose"].shape[1] == 2


@pytest.mark.parametrize("value", [".inf", "-.inf", ".nan", "1e300", "-3", "abc", "[1, 2]",
                                   "{a: 1}", "1000000000"])
def test_bad_agent_counts_from_the_command_line(tmp_path, capsys, value):
    t0 = time.perf_counter()
    rc, _o, err = run(["waypoints", "--set", f"agents={value}", "--out",
                       str(tmp_path / "o")], capsys)
    assert rc == 2, err
    assert err.startswith("avblocks: error: ") and err.count("\n") == 1
    assert "Traceback" not in err
    assert time.perf_counter() - t0 < 20
    assert not (tmp_path / "o" / "results.nc").exists()


def test_huge_generated_arrays_are_refused_with_the_figure(tmp_path, monkeypatch):
    text = BASE.replace("wires:", "  w: {type: blocks.Constant, value: {random_waypoints:"
                        " {n: 1000, count: 1000000000, area: [1, 1]}}}\nwires:")
    t0 = time.perf_counter()
    with pytest.raises(ScenarioError, match=r"random_waypoints would take 1.6e\+04 GB"):
        load_scenario(write(tmp_path, text)).build()
    assert time.perf_counter() - t0 < 5
    # the limit is the user's to set
    monkeypatch.setenv("AVBLOCKS_MAX_MEMORY", "1000")
    with pytest.raises(ScenarioError, match=r"zeros would take 2.4e-06 GB.*<= 1e-06 GB"):
        load_scenario(write(tmp_path, BASE.replace("parameters: {n: 2}",
                                                   "parameters: {n: 100}"))).build()


def test_cli_estimates_the_run_memory_before_simulating(tmp_path, capsys, monkeypatch):
    from avblocks._runio import estimate_bytes
    sc = load_scenario("waypoints").with_overrides({"agents": 200})
    d, sim = sc.build()
    need = estimate_bytes(d.build(), sim)
    # the log alone: 200 poses x 3 float64 per sample, t_final / dt + 1 samples
    samples = round(sim["t_final"] / sim["dt"]) // sim.get("log_every", 1) + 1
    assert need >= samples * 200 * 3 * 8
    assert need < 1.5 * samples * 200 * 3 * 8 + 1e6
    monkeypatch.setenv("AVBLOCKS_MAX_MEMORY", str(need // 2))
    rc, _o, err = run(["waypoints", "--set", "agents=200", "--out", str(tmp_path / "o")],
                      capsys)
    assert rc == 2 and f"about {need / 1e9:.3g} GB" in err
    assert not (tmp_path / "o" / "results.nc").exists()
