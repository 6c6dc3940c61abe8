"""A scenario with very many blocks is refused before it is parsed in full
or built (issue 22): in well under a second in-process, and through the
``avblocks`` executable, whatever way the file writes its blocks."""

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from avblocks.core.errors import ScenarioError
from avblocks.scenarios import load_scenario
from avblocks.scenarios.limits import MAX_BLOCKS

N = 100_000
GAIN = "{type: blocks.Gain, k: 2.0}"
YAML_FORMS = {
    "block style": "blocks:\n" + "".join(f"  g{i}: {GAIN}\n" for i in range(N)),
    "flow style": "blocks: {" + ", ".join(f"g{i}: {GAIN}" for i in range(N)) + "}\n",
    "aliases": "blocks:\n  g0: &b " + GAIN + "\n" + "".join(f"  g{i}: *b\n"
                                                          for i in range(1, N)),
    "blocks last": "name: big\nsimulation: {t_final: 1}\nblocks:\n"
                   + "".join(f"  g{i}: {GAIN}\n" for i in range(N)),
}
TOML_FORMS = {
    "dotted keys": "".join(f'blocks.g{i} = {{type = "blocks.Gain", k = 2.0}}\n'
                           for i in range(N)),
    "blocks table": "[blocks]\n" + "".join(f'g{i} = {{type = "blocks.Gain"}}\n'
                                           for i in range(N)),
    "table headers": "".join(f'[blocks.g{i}]\ntype = "blocks.Gain"\n' for i in range(N)),
}


def _write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.mark.parametrize("form", sorted(YAML_FORMS) + sorted(TOML_FORMS))
def test_many_blocks_refused_in_well_under_a_second(tmp_path, form):
    suffix = ".yaml" if form in YAML_FORMS else ".toml"
    p = _write(tmp_path, "many" + suffix, {**YAML_FORMS, **TOML_FORMS}[form])
    t = time.perf_counter()
    with pytest.raises(ScenarioError) as e:
        load_scenario(p)
    dt = time.perf_counter() - t
    assert "blocks" in str(e.value) and f"{MAX_BLOCKS:,}" in str(e.value)
    assert e.value.file == str(p) and e.value.entry == "blocks"
    assert dt < 0.5, f"{dt:.2f} s"


def test_blocks_in_a_merged_mapping_are_counted_after_the_parse(tmp_path, monkeypatch):
    """What the fast count cannot see (a merge key) is counted before the build."""
    monkeypatch.setenv("AVBLOCKS_MAX_BLOCKS", "3")
    text = ("parameters: &p {a: {type: blocks.Gain}, b: {type: blocks.Gain}, "
            "c: {type: blocks.Gain}, d: {type: blocks.Gain}}\nblocks: {<<: *p}\n")
    with pytest.raises(ScenarioError, match="4 blocks, more than the 3"):
        load_scenario(_write(tmp_path, "m.yaml", text))


def test_the_limit_can_be_raised(tmp_path, monkeypatch):
    text = "blocks:\n" + "".join(f"  g{i}: {GAIN}\n" for i in range(5))
    monkeypatch.setenv("AVBLOCKS_MAX_BLOCKS", "4")
    with pytest.raises(ScenarioError, match="more than 4 blocks"):
        load_scenario(_write(tmp_path, "a.yaml", text))
    monkeypatch.setenv("AVBLOCKS_MAX_BLOCKS", "5")
    assert len(load_scenario(_write(tmp_path, "b.yaml", text)).data["blocks"]) == 5


def test_a_scenario_at_the_limit_loads_and_runs(tmp_path):
    """MAX_BLOCKS blocks in a chain: accepted, built and simulated."""
    import numpy as np

    import avblocks as av
    from avblocks.scenarios.targets import load_any
    n = MAX_BLOCKS
    text = ("blocks:\n  c: {type: blocks.Constant, value: [[1.0, 2.0]]}\n"
            + "".join(f"  g{i}: {{type: blocks.Gain, k: 1.001}}\n" for i in range(n - 1))
            + "wires:\n  - [c.y, g0.u]\n"
            + "".join(f"  - [g{i}.y, g{i + 1}.u]\n" for i in range(n - 2))
            + f"simulation: {{t_final: 0.1, dt: 0.1, log: [g{n - 2}.y]}}\n")
    d, sim, *_ = load_any(str(_write(tmp_path, "chain.yaml", text)), {}, tmp_path / "o")
    res = av.simulate(d, **sim)
    np.testing.assert_allclose(res[f"g{n - 2}.y"][-1], [[1.001 ** (n - 1),
                                                          2 * 1.001 ** (n - 1)]])


def _avblocks(*args):
    exe = Path(sys.executable).with_name("avblocks")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "avblocks"]
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).parents[2] / "src")}
    t = time.perf_counter()
    p = subprocess.run([*cmd, *args], capture_output=True, text=True, env=env, timeout=120)
    return p, time.perf_counter() - t


def test_many_blocks_through_the_executable(tmp_path):
    p = _write(tmp_path, "many.yaml", YAML_FORMS["block style"])
    _, startup = _avblocks("--version")
    r, wall = _avblocks("run", str(p), "--out", str(tmp_path / "o"))
    assert r.returncode == 2, r.stderr
    assert "more than 2,000 blocks" in r.stderr and "Traceback" not in r.stderr
    assert wall - startup < 1.0, f"{wall:.2f} s against {startup:.2f} s to start"


def test_agents_times_blocks_past_the_memory_limit(tmp_path, monkeypatch):
    """Each generated array within the limit, all of them together past it:
    refused at the block that crosses it, before the diagram is built."""
    monkeypatch.setenv("AVBLOCKS_MAX_MEMORY", "1000000")          # 1 MB
    blocks = "".join(f"  f{i}: {{type: vehicles.Unicycle, pose0: {{zeros: "
                     f"{{shape: [20000, 3]}}}}}}\n" for i in range(3))    # 0.48 MB each
    p = _write(tmp_path, "m.yaml", "blocks:\n" + blocks)
    from avblocks.scenarios.targets import load_any
    with pytest.raises(ScenarioError) as e:
        load_any(str(p), {}, tmp_path / "o")
    assert e.value.entry == "blocks.f2.pose0" and "0.00144 GB in all" in str(e.value)
    monkeypatch.setenv("AVBLOCKS_MAX_MEMORY", "2000000")
    with pytest.raises(ScenarioError, match="input is not connected|every input"):
        load_any(str(p), {}, tmp_path / "o")              # gets as far as the wiring
