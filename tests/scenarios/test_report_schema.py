"""The ``outcome:`` / ``figures:`` / ``report:`` sections are validated when
the file is loaded (issue 22): known names, arguments the Python function
takes, types and ranges, figure formats, and signals the run will log,
each refused with a ScenarioError naming the file and the entry."""

import inspect

import pytest

import avblocks as av
from avblocks.scenarios import _report_schema as schema
from avblocks.scenarios import load_scenario
from avblocks.scenarios.targets import load_any

BASE = """
name: tiny
blocks:
  fleet: {type: vehicles.Unicycle, pose0: {zeros: {shape: [3, 3]}}}
  drive: {type: controllers.PointToPoint, waypoints: [[[1, 1]], [[2, 2]], [[3, 3]]]}
wires: [[fleet.pose, drive.pose], [drive.cmd, fleet.cmd]]
simulation: {t_final: 0.2, dt: 0.1, log: [fleet.pose, drive.done]}
"""

# (section text, entry the error names, words in the message) refused by load_scenario
STRUCTURE = [
    ("outcome: [{metric: {a: 1}, signal: fleet.pose}]", "outcome[0].metric", "unknown metric"),
    ("outcome: [{metric: [all_true], signal: drive.done}]", "outcome[0].metric", "unknown"),
    ("outcome: [{metric: all_true, signal: drive.done, colour: red}]",
     "outcome[0].colour", "takes no argument 'colour'"),
    ("outcome: [{metric: all_true}]", "outcome[0]", "needs ['signal']"),
    ("outcome: [{metric: all_true, signal: {a: 1}}]", "outcome[0].signal", "'signal' must be"),
    ("outcome: [{metric: all_true, signal: 5}]", "outcome[0].signal", "'signal' must be"),
    ("outcome: [{metric: final_mean, signal: fleet.pose, component: x}]",
     "outcome[0].component", "whole number"),
    ("outcome: [{metric: final_mean, signal: fleet.pose, component: 1.5}]",
     "outcome[0].component", "whole number"),
    ("outcome: [{metric: min_distance, signal: fleet.pose, label: [1]}]",
     "outcome[0].label", "a string"),
    ("outcome: {metric: all_true}", "outcome", "must be a list"),
    ("outcome: [{1: 2}]", "outcome[0]", "needs 'metric'"),
    ("figures: [{plot: trajectories, file: a.png, linewidth: 3}]",
     "figures[0].linewidth", "takes no argument 'linewidth'"),
    ("figures: [{plot: fraction, file: a.png, signal: drive.done, ax: 1}]",
     "figures[0].ax", "takes no argument 'ax'"),
    ("figures: [{plot: signals, file: a.png, signals: fleet.pose, fig: 1}]",
     "figures[0].fig", "takes no argument"),
    ("figures: [{plot: trajectories, file: !!str png}]", "figures[0].file", "no known format"),
    ("figures: [{plot: trajectories, file: a.xyz}]", "figures[0].file", "no known format"),
    ("figures: [{plot: trajectories, file: a}]", "figures[0].file", "no known format"),
    ("figures: [{plot: trajectories, file: {a: 1}}]", "figures[0].file", "file name"),
    ("figures: [{plot: trajectories, file: /tmp/x.png}]", "figures[0].file", "leaves"),
    ("figures: [{plot: trajectories, file: ../x.png}]", "figures[0].file", "leaves"),
    ("figures: [{plot: {a: 1}, file: a.png}]", "figures[0].plot", "unknown plot"),
    ("figures: [{plot: trajectories, file: a.png, pose: {a: 1}}]", "figures[0].pose",
     "logged signal"),
    ("figures: [{plot: trajectories, file: a.png, figsize: [1e9, 3]}]",
     "figures[0].figsize", "inches"),
    ("figures: [{plot: trajectories, file: a.png, figsize: [a, b]}]",
     "figures[0].figsize", "inches"),
    ("figures: [{plot: trajectories, file: a.png, waypoints: [[1, 2, 3]]}]",
     "figures[0].waypoints", "(W, 2)"),
    ("figures: [{plot: trajectories, file: a.png, waypoints: [[.nan, 2]]}]",
     "figures[0].waypoints", "(W, 2)"),
    ("figures: [{plot: trajectories, file: a.png, waypoints: {a: 1}}]",
     "figures[0].waypoints", "block name"),
    ("figures: [{plot: trajectories, file: a.png, obstacles: [[1, 2]]}]",
     "figures[0].obstacles", "vertices"),
    ("figures: [{plot: trajectories, file: a.png, agents: [-1]}]", "figures[0].agents",
     "agent index"),
    ("figures: [{plot: trajectories, file: a.png, agents: {a: 1}}]", "figures[0].agents",
     "agent index"),
    ("figures: [{plot: trajectories, file: a.png, color: notacolour}]", "figures[0].color",
     "colour"),
    ("figures: [{plot: trajectories, file: a.png, cmap: nope}]", "figures[0].cmap",
     "colour map"),
    ("figures: [{plot: trajectories, file: a.png, drawing: nope}]", "figures[0].drawing",
     "drawings"),
    ("figures: [{plot: trajectories, file: a.png, max_points: 1e12}]",
     "figures[0].max_points", "whole number"),
    ("figures: [{plot: trajectories, file: a.png, legend: maybe}]", "figures[0].legend",
     "true or false"),
    ("figures: [{plot: signals, file: a.png}]", "figures[0]", "needs ['signals']"),
    ("figures: [{plot: signals, file: a.png, signals: [fleet.pose, [1]]}]",
     "figures[0].signals", "logged signal"),
    ("figures: [{plot: signals, file: a.png, signals: fleet.pose, band: [90, 10]}]",
     "figures[0].band", "increasing"),
    ("report: {a: 1}", "report", "unknown report"),
    ("report: [nest]", "report", "unknown report"),
]


@pytest.mark.parametrize("extra, entry, words", STRUCTURE)
def test_report_sections_are_checked_at_load(tmp_path, extra, entry, words):
    p = tmp_path / "s.yaml"
    p.write_text(BASE + extra + "\n")
    with pytest.raises(av.ScenarioError) as e:
        load_scenario(p)
    assert e.value.file == str(p) and e.value.entry == entry, str(e.value)
    assert words in str(e.value)


def test_unknown_argument_error_lists_the_allowed_names(tmp_path):
    p = tmp_path / "s.yaml"
    p.write_text(BASE + "figures: [{plot: fraction, file: a.png, signal: drive.done, "
                        "titel: x}]\n")
    with pytest.raises(av.ScenarioError) as e:
        load_scenario(p)
    msg = str(e.value)
    assert "did you mean 'title'" in msg
    assert "['file', 'label', 'signal', 'title']" in msg


# refused once the diagram is built (what is logged, and its shape)
LOGGED = [
    ("outcome: [{metric: all_true, signal: drive.target}]", "outcome[0].signal",
     "'drive.target' will not be logged"),
    ("outcome: [{metric: all_true, signal: nope.x}]", "outcome[0].signal",
     "will not be logged"),
    ("outcome: [{metric: min_distance, signal: drive.done}]", "outcome[0].signal",
     "shape (3,)"),
    ("outcome: [{metric: final_mean, signal: fleet.pose, component: 3}]",
     "outcome[0].component", "out of range"),
    ("figures: [{plot: trajectories, file: a.png, pose: drive.done}]", "figures[0].pose",
     "shape (3,)"),
    ("figures: [{plot: trajectories, file: a.png, pose: drive.cmd}]", "figures[0].pose",
     "will not be logged"),
    ("figures: [{plot: trajectories, file: a.png, agents: [0, 3]}]", "figures[0].agents",
     "out of range"),
    ("figures: [{plot: trajectories, file: a.png, color: fleet.pose}]", "figures[0].color",
     "one value per agent"),
    ("figures: [{plot: trajectories, file: a.png, waypoints: fleet}]",
     "figures[0].waypoints", "has no waypoints"),
    ("figures: [{plot: trajectories, file: a.png, waypoints: nope}]",
     "figures[0].waypoints", "names no block"),
    ("figures: [{plot: fraction, file: a.png, signal: fleet.cmd}]", "figures[0].signal",
     "will not be logged"),
    ("figures: [{plot: signals, file: a.png, signals: [fleet.pose, drive.cmd]}]",
     "figures[0].signals", "will not be logged"),
]


@pytest.mark.parametrize("extra, entry, words", LOGGED)
def test_signals_must_be_logged_with_a_usable_shape(tmp_path, extra, entry, words):
    p = tmp_path / "s.yaml"
    p.write_text(BASE + extra + "\n")
    load_scenario(p)                               # the structure is fine
    with pytest.raises(av.ScenarioError) as e:
        load_any(str(p), {}, tmp_path / "out")
    assert e.value.file == str(p) and e.value.entry == entry, str(e.value)
    assert words in str(e.value)


def test_default_log_counts_as_logged(tmp_path):
    """Without simulation.log only pose/position outputs are logged."""
    p = tmp_path / "s.yaml"
    p.write_text(BASE.replace(", log: [fleet.pose, drive.done]", "")
                 + "outcome: [{metric: all_true, signal: drive.done}]\n")
    with pytest.raises(av.ScenarioError, match="'drive.done' will not be logged"):
        load_any(str(p), {}, tmp_path / "out")
    p.write_text(BASE.replace(", log: [fleet.pose, drive.done]", "")
                 + "figures: [{plot: trajectories, file: a.png}]\n")
    assert load_any(str(p), {}, tmp_path / "out").hooks.figures is not None


def test_bad_log_is_refused_before_the_run(tmp_path):
    p = tmp_path / "s.yaml"
    p.write_text(BASE.replace("log: [fleet.pose, drive.done]", "log: [fleet.nope]")
                 + "outcome: [{metric: all_true, signal: fleet.pose}]\n")
    with pytest.raises(av.ScenarioError) as e:
        load_any(str(p), {}, tmp_path / "out")
    assert e.value.entry == "simulation.log" and "nope" in str(e.value)


def test_valid_sections_run_and_give_the_right_numbers(tmp_path, monkeypatch):
    """Every metric and plot with every argument, accepted and used."""
    import json

    import numpy as np

    from avblocks.cli import main
    p = tmp_path / "s.yaml"
    p.write_text(BASE.replace("t_final: 0.2", "t_final: 1.0") + """
outcome:
  - {metric: all_true, signal: drive.done, what: arrived}
  - {metric: min_distance, signal: fleet.pose, label: closest}
  - {metric: final_mean, signal: fleet.pose, component: 0, unit: m, label: mean x}
figures:
  - {plot: trajectories, file: sub/t.svg, pose: fleet.pose, agents: [0, 2],
     color: drive.done, color_labels: [going, there], cmap: viridis, clim: [0, 1],
     drawing: unicycle, size: 0.2, obstacles: [[[0, 0], [1, 0], [1, 1]]],
     waypoints: drive, title: T, legend: false, max_points: 50, figsize: [4, 3]}
  - {plot: trajectories, file: w.pdf, waypoints: [[1, 1], [2, 2]]}
  - {plot: signals, file: s.png, signals: [fleet.pose, drive.done], agents: 1,
     components: [0], max_lines: 3, band: [10, 90], figsize: [5, 4], title: S}
  - {plot: fraction, file: f.png, signal: drive.done, label: done, title: F}
""")
    monkeypatch.chdir(tmp_path)
    assert main(["run", str(p), "--out", "o", "--quiet"]) == 0
    s = json.loads((tmp_path / "o" / "summary.json").read_text())
    res = av.Results.load(tmp_path / "o" / "results.nc")
    x = np.asarray(res["fleet.pose"])[-1, :, 0].mean()
    assert s["numbers"]["fleet_pose_final_mean"] == pytest.approx(x)
    assert f"mean x {x:.3g} m" in s["outcome"]
    for f in ("sub/t.svg", "w.pdf", "s.png", "f.png"):
        assert (tmp_path / "o" / f).stat().st_size > 1000


def test_schema_names_are_arguments_of_the_functions():
    """The schema never offers a name the Python function does not take."""
    for name, fn in schema._targets().items():
        params = inspect.signature(fn).parameters
        offered = {**schema.METRIC_ARGS, **schema.PLOT_ARGS}[name]
        assert set(offered) <= set(params), (name, set(offered) - set(params))
        assert schema.allowed_arguments(name) == offered


def test_a_metric_failing_while_it_runs_names_its_entry():
    """What the load checks cannot foresee ends as a ScenarioError naming the entry."""
    import numpy as np

    from avblocks.scenarios.report import hooks_from_data
    hooks = hooks_from_data([{"metric": "min_distance", "signal": "a.b"}], None,
                            source="s.yaml", check_log=False)
    res = av.Results(np.arange(3.0), {"a.b": np.zeros(3)})
    with pytest.raises(av.ScenarioError) as e:
        hooks.outcome(res)
    assert e.value.entry == "outcome[0]" and "min_distance" in str(e.value)


@pytest.mark.parametrize("extra, entry", [
    ("figures: [{plot: signals, file: a.png, signals: [fleet.pose, drive.done], "
     "components: [0, 1]}]", "figures[0].components"),
    ("figures: [{plot: signals, file: a.png, signals: fleet.pose, components: [3]}]",
     "figures[0].components"),
    ("figures: [{plot: signals, file: a.png, signals: fleet.pose, agents: 3}]",
     "figures[0].agents"),
])
def test_signals_plot_components_and_agents_exist(tmp_path, extra, entry):
    p = tmp_path / "s.yaml"
    p.write_text(BASE + extra + "\n")
    with pytest.raises(av.ScenarioError) as e:
        load_any(str(p), {}, tmp_path / "out")
    assert e.value.entry == entry and "out of range" in str(e.value)


@pytest.mark.parametrize("name", ["nest", "formation", "flocking", "swap"])
def test_report_signals_must_be_logged(tmp_path, name):
    """``report: <case study>`` on a file that does not log what the case
    study reads is refused at load, naming the signals; the built-in files
    log exactly what their report reads."""
    import yaml

    from avblocks.scenarios.loader import builtin_dir
    from avblocks.scenarios.report import REPORT_SIGNALS
    data = yaml.safe_load((builtin_dir() / f"{name}.yaml").read_text())
    assert data["report"] == name
    assert set(data["simulation"]["log"]) == set(REPORT_SIGNALS[name])
    p = tmp_path / f"{name}.yaml"
    p.write_text(yaml.safe_dump(data))
    assert load_any(str(p), {}, tmp_path / "o").hooks.outcome is not None
    dropped = data["simulation"]["log"].pop()
    p.write_text(yaml.safe_dump(data))
    with pytest.raises(av.ScenarioError) as e:
        load_any(str(p), {}, tmp_path / "o")
    assert e.value.entry == "report" and dropped in str(e.value)


def test_a_figure_never_follows_a_link_out_of_the_output_folder(tmp_path, capsys):
    """A project someone shares can carry ``avblocks-out/<name>/figs`` as a
    symbolic link to another folder; a scenario whose figure is
    ``figs/paths.png`` wrote through it (attack42). Resolved, a figure's
    name must stay inside the output folder: the run stops with the
    scenario's entry named and nothing is written where the link points."""
    import os

    from avblocks.cli import main
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    project = tmp_path / "project"
    (project / "avblocks-out" / "demo").mkdir(parents=True)
    os.symlink(outside, project / "avblocks-out" / "demo" / "figs")
    scenario = project / "demo.yaml"
    scenario.write_text(
        "name: demo\nparameters: {agents: 2, seed: 1}\nblocks:\n"
        "  fleet: {type: vehicles.Unicycle, pose0: {random_poses: {n: $agents, "
        "area: [5, 5], seed: $seed}}}\n"
        "  drive: {type: controllers.PointToPoint, waypoints: {random_waypoints: "
        "{n: $agents, count: 2, area: [5, 5], seed: $seed}}}\n"
        "wires: [[fleet.pose, drive.pose], [drive.cmd, fleet.cmd]]\n"
        "simulation: {t_final: 0.2, dt: 0.1, log: [fleet.pose]}\n"
        "figures: [{plot: trajectories, file: figs/paths.png}]\n")
    cwd = os.getcwd()
    os.chdir(project)
    try:
        code = main(["run", "demo.yaml"])
    finally:
        os.chdir(cwd)
    err = capsys.readouterr().err
    assert code != 0 and "figures[0].file" in err and "outside the folder" in err, err
    assert list(outside.iterdir()) == []
    # the same name in a real sub-folder is written
    os.unlink(project / "avblocks-out" / "demo" / "figs")
    os.chdir(project)
    try:
        assert main(["run", "demo.yaml"]) == 0
    finally:
        os.chdir(cwd)
    assert (project / "avblocks-out" / "demo" / "figs" / "paths.png").stat().st_size > 1000
