"""Scenario files are data: they write only inside the output folder, read
only under their own folder, and every malformed file gets one clear line."""

import json
import os
import re
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

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


@pytest.mark.parametrize("bad", ["p\x00.npz", "\u00e9\x00", "a" * 5000])
def test_a_path_value_that_cannot_name_a_file_is_one_clean_line(tmp_path, bad):
    """A file path in a scenario file holding a NUL or longer than PATH_MAX:
    one ScenarioError naming the entry (the schema fuzz found 'é\\x00' as
    navigation's policy path ending in os.path.realpath's ValueError)."""
    import yaml

    from avblocks.scenarios.loader import builtin_scenarios
    data = yaml.safe_load(builtin_scenarios()["navigation"].read_text())
    data["blocks"]["command"]["policy"] = bad
    f = tmp_path / "nav.yaml"
    f.write_text(yaml.safe_dump(data))
    with pytest.raises(ScenarioError, match="is not a file path") as e:
        load_scenario(f).build(output_dir=tmp_path / "out")
    assert "blocks.command" in str(e.value) and len(str(e.value)) < 400


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


@pytest.mark.parametrize("where", ["--set", "file"])
@pytest.mark.parametrize("dt", ["0", "0.0", "-0.0"])
def test_a_zero_time_step_is_one_line_naming_dt(tmp_path, capsys, where, dt):
    """``--set simulation.dt=0`` (or ``dt: 0`` in the file) ended in a
    ZeroDivisionError traceback from the memory estimate (attack42)."""
    if where == "file":
        f = write(tmp_path, BASE.replace("dt: 0.1", f"dt: {dt}"))
        rc, _o, err = run([str(f), "--out", str(tmp_path / "o")], capsys)
    else:
        f = write(tmp_path, BASE)
        rc, _o, err = run([str(f), "--set", f"simulation.dt={dt}", "--out",
                           str(tmp_path / "o")], capsys)
    assert rc == 2 and err.startswith("avblocks: error: ") and "'dt'" in err, err
    assert "Traceback" not in err and err.count("\n") == 1


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


# ------------------------------------------------------------ hostile shapes
# Files shaped to hurt a parser or a walker rather than to be wrong: deep
# nesting (flow, block style, through anchors), alias bombs, huge numbers,
# huge strings, huge files, files that are not regular files. Each must end
# in a ScenarioError naming the file (and, for a limit, the limit), never a
# traceback, a hang or a crash. `benchmarks/scenario_fuzz.py` counts how
# `avblocks run` answers the same cases.

def _with_block(value):
    return BASE.replace("wires:", f"  k: {{type: blocks.Constant, value: {value}}}\nwires:")


def _deep_list(d):
    return "[" * d + "1" + "]" * d


def _deep_map(d):
    return "{a: " * d + "1" + "}" * d


def _block_style(d):
    """A list nested ``d`` deep in YAML's block style (``- - - 1``)."""
    return BASE.replace("wires:", "  k:\n    type: blocks.Constant\n    value:\n      "
                        + "- " * d + "1\nwires:")


def _anchor_chain(d):
    """Depth made of aliases: each anchor wraps the one before."""
    items = ["&a0 [1]"] + [f"&a{i} [*a{i - 1}]" for i in range(1, d)]
    return BASE.replace("parameters: {n: 2}", "parameters: {n: 2, chain: ["
                        + ", ".join(items) + "]}")


def _bomb_lists():
    lines = ["a0: &a0 [x, x, x, x, x, x, x, x, x, x]"]
    lines += [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 10)}]" for i in range(1, 10)]
    return "\n".join(lines) + "\n" + BASE


def _bomb_maps():
    lines = ["a0: &a0 {" + ", ".join(f"k{j}: x" for j in range(10)) + "}"]
    for i in range(1, 10):
        refs = ", ".join(f"k{j}: *a{i - 1}" for j in range(10))
        lines.append(f"a{i}: &a{i} {{{refs}}}")
    return "\n".join(lines) + "\n" + BASE


def _in_section(section, value):
    """``value`` placed in one section of the tiny scenario."""
    if section == "parameters":
        return BASE.replace("parameters: {n: 2}", f"parameters: {{n: 2, x: {value}}}")
    if section == "simulation":
        return BASE.replace("dt: 0.1}", f"dt: 0.1, log: {value}}}")
    if section == "wires":
        return BASE.replace("  - [c.y, fleet.cmd]", f"  - [c.y, fleet.cmd]\n  - {value}")
    if section == "whole file":
        return value
    return BASE + f"{section}: {value}\n"


SECTIONS = ["parameters", "simulation", "wires", "params", "movie", "outcome", "figures",
            "editor", "name", "description", "report", "whole file"]
BIG = 5_000_000          # characters of the huge strings (half the file limit)


def hostile_cases():
    """``[(id, suffix, build)]``: ``build()`` returns the file's bytes, or a
    string naming a special file (``"fifo"``, ``"/dev/zero"``)."""
    cases = []

    def add(name, build, suffix=".yaml"):
        cases.append((name, suffix, build))

    for d in (50, 200, 500, 1000, 5000, 100_000):
        add(f"deep list {d}", lambda d=d: _with_block(_deep_list(d)))
    for d in (500, 5000):
        add(f"deep mapping {d}", lambda d=d: _with_block(_deep_map(d)))
    for d in (300, 1500):
        add(f"deep block style {d}", lambda d=d: _block_style(d))
    for s in SECTIONS:
        add(f"deep {s}", lambda s=s: _in_section(s, _deep_list(700)))
    add("deep anchor chain 150", lambda: _anchor_chain(150))
    add("deep anchor chain 2000", lambda: _anchor_chain(2000))
    add("alias bomb (lists)", _bomb_lists)
    add("alias bomb (mappings)", _bomb_maps)
    add("self-referencing alias", lambda: BASE.replace("parameters: {n: 2}",
                                                       "parameters: &p {n: 2, me: *p}"))
    for digits in (400, 4000, 5000):
        big = "9" * digits
        add(f"{digits}-digit agent count",
            lambda big=big: BASE.replace("parameters: {n: 2}", f"parameters: {{n: {big}}}"))
        add(f"{digits}-digit t_final",
            lambda big=big: BASE.replace("t_final: 0.5", f"t_final: {big}"))
    add("1e400 dt", lambda: BASE.replace("dt: 0.1", "dt: 1e400"))
    add("-1e400 t_final", lambda: BASE.replace("t_final: 0.5", "t_final: -1.0e+400"))
    add("2^64 seed", lambda: BASE.replace("dt: 0.1}", f"dt: 0.1, seed: {2**64}}}"))
    huge = "x" * BIG
    for where, text in [
        ("name", lambda: BASE.replace("name: tiny", f"name: {huge}")),
        ("description", lambda: BASE + f"description: {huge}\n"),
        ("block name", lambda: BASE.replace("  c: {", f"  {huge[:1_000_000]}: {{")),
        ("block type", lambda: BASE.replace("blocks.Constant", huge)),
        ("parameter", lambda: BASE.replace("parameters: {n: 2}",
                                           f"parameters: {{n: 2, s: {huge}}}")),
        ("wire end", lambda: BASE.replace("[c.y, fleet.cmd]", f"[c.{huge}, fleet.cmd]")),
        ("section key", lambda: BASE + f"{huge[:1_000_000]}: 1\n"),
        ("solver", lambda: BASE.replace("dt: 0.1}", f"dt: 0.1, solver: {huge}}}")),
        ("report", lambda: BASE + f"report: {huge}\n"),
        ("generator key", lambda: _with_block(f"{{{huge[:1_000_000]}: {{n: 2}}}}")),
    ]:
        add(f"huge string: {where}", text)
    add("file over the size limit", lambda: BASE + "#" * (11 * 1024**2) + "\n")
    add("a million values", lambda: BASE.replace(
        "parameters: {n: 2}", "parameters: {n: 2, v: [" + ",".join(["1"] * 1_100_000)
        + "]}"))
    add("100,000 parameters", lambda: BASE.replace(
        "parameters: {n: 2}", "parameters: {n: 2, "
        + ", ".join(f"p{i}: {i}" for i in range(100_000)) + "}"))
    add("3,000 blocks", lambda: BASE.replace("blocks:", "blocks:\n" + "".join(
        f"  b{i}: {{type: blocks.Constant, value: 1.0}}\n" for i in range(3000))))
    toml = ('name = "tiny"\n[parameters]\nn = 2\n[blocks.fleet]\ntype = "vehicles.Unicycle"'
            '\npose0 = {zeros = {shape = [2, 3]}}\n[blocks.c]\ntype = "blocks.Constant"\n'
            'value = [[1.0, 0.0], [1.0, 0.0]]\nVALUE\n[simulation]\nt_final = 0.5\n'
            'dt = 0.1\n')
    wires = 'wires = [["c.y", "fleet.cmd"]]'
    for d in (500, 5000, 100_000):
        add(f"TOML deep array {d}", lambda d=d: toml.replace("VALUE", "deep = " + _deep_list(d))
            .replace("[simulation]", wires + "\n[simulation]"), ".toml")
    add("TOML deep inline table 5000", lambda: toml.replace(
        "VALUE", "deep = " + "{a = " * 5000 + "1" + "}" * 5000), ".toml")
    add("TOML deep dotted key 5000", lambda: toml.replace(
        "VALUE", ".".join(["a"] * 5000) + " = 1"), ".toml")
    add("TOML 5000-digit integer", lambda: toml.replace("n = 2", "n = " + "9" * 5000),
        ".toml")
    add("special: FIFO", lambda: "fifo")
    add("special: /dev/zero", lambda: "/dev/zero")
    add("special: /dev/urandom", lambda: "/dev/urandom")
    add("special: symlink loop", lambda: "loop")
    return cases


def make_hostile(folder, case):
    """Write one of :func:`hostile_cases` into ``folder``; its path."""
    name, suffix, build = case
    p = Path(folder) / f"hostile{suffix}"
    content = build()
    if content == "fifo":
        os.mkfifo(p)
    elif content == "loop":
        p.symlink_to(p)
    elif isinstance(content, str) and content.startswith("/dev/"):
        p.symlink_to(content)
    else:
        p.write_bytes(content.encode() if isinstance(content, str) else content)
    return p


#: what each hostile case must be answered with (a regular expression of
#: the error line), or None: the file is valid and runs
DEEP = "values nest deeper than 100 levels"
EXPECTED = {
    "deep list 50": None, "-1e400 t_final": None, "100,000 parameters": None,
    "deep anchor chain 2000": "expand to more than 1,000,000 values",
    "alias bomb (lists)": "expand to more than", "alias bomb (mappings)": "expand to more than",
    "self-referencing alias": "recursive structure",
    "1e400 dt": r"'dt'.*found (inf|1e400)", "2^64 seed": r"'seed'.*out of range",
    "huge string: block name": "cannot parse", "huge string: section key": "cannot parse",
    "huge string: generator key": r"1,000,000 characters.*more than 100,000",
    "file over the size limit": "at most 10 MB",
    "a million values": "more than 1,000,000 values",
    "3,000 blocks": "more than 2,000 blocks",
    "special: symlink loop": "cannot read: Too many levels of symbolic links",
}
for _name, *_ in hostile_cases():
    if _name.startswith(("deep", "TOML deep")):
        EXPECTED.setdefault(_name, DEEP)
    elif "digit" in _name:
        EXPECTED.setdefault(_name, r"whole number of .*digits.*more than 100")
    elif _name.startswith("huge string"):
        EXPECTED.setdefault(_name, r"a text of 5,000,0\d\d characters.*more than 100,000")
    elif _name.startswith("special"):
        EXPECTED.setdefault(_name, "is not a regular file")
SLOW_CASES = {"a million values", "100,000 parameters"}


@pytest.mark.parametrize("case", [
    pytest.param(c, id=c[0], marks=[pytest.mark.slow] if c[0] in SLOW_CASES else [])
    for c in hostile_cases()])
def test_hostile_shapes_get_one_clean_line(tmp_path, capsys, case):
    """`avblocks run` on each hostile shape: exit status 2 and one error line
    naming the file and the limit (or a run, for the valid ones), never a
    traceback; the file's shape is refused before anything recursive walks
    it, so none takes long."""
    p = make_hostile(tmp_path, case)
    t0 = time.perf_counter()
    rc, _o, err = run([str(p), "--out", str(tmp_path / "o"), "--t-final", "0.2"], capsys)
    took = time.perf_counter() - t0
    want = EXPECTED[case[0]]
    assert "Traceback" not in err
    if want is None:
        assert rc == 0, err
        return
    assert rc == 2, err
    assert err.startswith("avblocks: error: ") and err.count("\n") == 1, err[:300]
    assert re.search(want, err), err[:300]
    if not want.startswith("'"):                 # a file's problem names the file
        assert str(p) in err
    if case[0] not in SLOW_CASES:
        assert took < 20


def test_deep_values_from_outside_a_file_are_refused_by_the_loader(tmp_path, capsys):
    """A scenario mapping (the editor's document, a sweep's) and a --set
    value are checked like a file before anything walks them."""
    from avblocks.scenarios import Scenario
    data = {"name": "x", "blocks": {"k": {"type": "blocks.Constant", "value": 1.0}}}
    v = 1.0
    for _ in range(5000):
        v = [v]
    deep = {**data, "blocks": {"k": {"type": "blocks.Constant", "value": v}}}
    for call in (lambda: Scenario(deep, "doc.yaml").build(),
                 lambda: Scenario(deep, "doc.yaml").with_overrides({}),
                 lambda: Scenario(data, "doc.yaml").with_overrides({"x": v})):
        with pytest.raises(ScenarioError, match=f"doc.yaml.*{DEEP}"):
            call()
    for bad, what in ((["x" * 100_001], "a text of 100,001 characters"),
                      ({"k" * 1001: 1}, "a key of 1,001 characters"),
                      (10 ** 200, "whole number of about 200 digits")):
        with pytest.raises(ScenarioError, match=what):
            Scenario({**data, "description": bad}, "doc.yaml").validate()
    p = write(tmp_path, BASE)
    rc, _o, err = run([str(p), "--set", "n=" + "[" * 3000 + "]" * 3000], capsys)
    assert rc == 2 and "Traceback" not in err and DEEP in err


def test_limits_leave_ordinary_files_alone(tmp_path):
    """Every built-in scenario file loads and builds under the limits, and
    nesting up to the limit itself is accepted."""
    from avblocks.scenarios.limits import MAX_DEPTH, check_values
    from avblocks.scenarios.loader import builtin_scenarios
    for name, path in builtin_scenarios().items():
        if path.suffix == ".yaml":
            load_scenario(name).with_overrides({})
    v = 1
    for _ in range(MAX_DEPTH):
        v = [v]
    check_values(v)                      # MAX_DEPTH lists inside each other
    with pytest.raises(ScenarioError, match=DEEP):
        check_values([v])


# the fuzz: a random hostile shape in a random section
SHAPES = st.sampled_from(["list", "mapping", "block style", "anchor chain", "digits",
                          "text"])


def _hostile_text(shape, size, section):
    if shape == "block style":
        return _block_style(size)
    if shape == "anchor chain":
        return _anchor_chain(size)
    value = {"list": _deep_list, "mapping": _deep_map}.get(shape)
    value = value(size) if value else ("9" * size if shape == "digits" else "x" * size * 50)
    return _with_block(value) if section == "block value" else _in_section(section, value)


@settings(max_examples=60, deadline=None, database=None,
          suppress_health_check=list(HealthCheck))
@given(shape=SHAPES, size=st.integers(1, 3000),
       section=st.sampled_from(SECTIONS + ["block value"]))
def test_fuzz_hostile_shapes(shape, size, section):
    """Load, override and build: a result or a one-line ScenarioError naming
    the file; a list or mapping nested past the limit always names it."""
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "s.yaml"
        p.write_text(_hostile_text(shape, size, section))
        try:
            load_scenario(p).with_overrides({}).build(output_dir=Path(tmp) / "o")
        except ScenarioError as e:
            assert str(p) in str(e) and "\n" not in str(e)
            if shape in ("list", "mapping") and size > 100 and section != "whole file":
                assert DEEP in str(e) or "expand to" in str(e), str(e)
            return
        except av.AvError:
            return                       # a value a block refuses: clean too
        assert not (shape in ("list", "mapping", "block style") and size > 100)


def test_a_report_name_is_one_of_ours_where_its_module_is_imported():
    """``report:`` picks a case study's module by name: checked when the file
    is validated, and again where ``avblocks.scenarios.<name>`` is imported."""
    from avblocks.scenarios.report import hooks_from_report
    for name in ("loader", "targets", "../x", "nest.yaml", 5):
        with pytest.raises(ScenarioError, match="unknown report"):
            hooks_from_report(name, {}, source="s.yaml")
