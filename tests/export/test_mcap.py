"""Runs as MCAP files, read back independently of the writer (tests/export/_read.py:
the mcap reader, protobuf decoded from the schemas inside the file, JSON
checked against the JSON schemas inside the file) and compared with the
results they came from: schemas, channels, timestamps and values."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

import avblocks as av
from avblocks.cli import main
from avblocks.core.errors import AvError, ParameterError

from ._read import need_readers, read, stamp_ns


@pytest.fixture(autouse=True)
def _readers():
    need_readers()
    if not os.environ.get("CI"):
        pytest.importorskip("foxglove")


def _ns(t):
    return np.round(np.asarray(t) * 1e9).astype(np.int64)


def test_a_case_study_folder_exported_with_the_cli_reads_back_as_its_results(tmp_path,
                                                                             capsys):
    out = tmp_path / "run"
    assert main(["run", "formation", "--t-final", "4", "--out", str(out), "--quiet"]) == 0
    assert main(["export", str(out), "--mcap"]) == 0
    assert "sim.mcap" in capsys.readouterr().out
    res = av.Results.load(out / "results.nc")
    summary = json.loads((out / "summary.json").read_text())
    msgs, summ, meta = read(out / "sim.mcap")
    n_t, n = res["fleet.pose"].shape[:2]
    # schemas and channels
    kinds = {c.topic: (summ.schemas[c.schema_id].name, summ.schemas[c.schema_id].encoding)
             for c in summ.channels.values()}
    assert kinds["/sim/tf"] == ("foxglove.FrameTransforms", "protobuf")
    assert kinds["/sim/bodies"] == ("foxglove.SceneUpdate", "protobuf")
    assert kinds["/sim/world"] == ("foxglove.SceneUpdate", "protobuf")
    assert kinds["/sim/links"] == ("foxglove.SceneUpdate", "protobuf")
    assert kinds["/sim/log"] == ("foxglove.Log", "protobuf")
    for key in res.keys():
        assert kinds[f"/sim/signals/{key}"] == (f"avblocks.{key}", "jsonschema")
    # one transform message per sample, at the sample's time, with every agent
    tf = msgs["/sim/tf"]
    assert [m.log_time for m in tf] == list(_ns(res.t))
    assert [m.publish_time for m in tf] == list(_ns(res.t))
    pose = res["fleet.pose"]
    for j, m in enumerate(tf):
        trs = m.value.transforms
        assert [tr.child_frame_id for tr in trs] == [f"sim/fleet/{i}" for i in range(n)]
        assert {tr.parent_frame_id for tr in trs} == {"world"}
        assert {stamp_ns(tr.timestamp) for tr in trs} == {int(_ns(res.t[j]))}
        xyz = np.array([[tr.translation.x, tr.translation.y, tr.translation.z] for tr in trs])
        np.testing.assert_allclose(xyz, np.column_stack([pose[j, :, :2], np.zeros(n)]),
                                   atol=1e-12)
        q = np.array([[tr.rotation.x, tr.rotation.y, tr.rotation.z, tr.rotation.w]
                      for tr in trs])
        half = pose[j, :, 2] / 2
        np.testing.assert_allclose(q, np.column_stack([0 * half, 0 * half, np.sin(half),
                                                       np.cos(half)]), atol=1e-12)
    # bodies: one entity per agent, locked to its frame, once at t = 0
    (bodies,) = msgs["/sim/bodies"]
    ents = bodies.value.entities
    assert [e.frame_id for e in ents] == [f"sim/fleet/{i}" for i in range(n)]
    assert all(e.frame_locked and e.lines for e in ents) and bodies.log_time == 0
    # the world: the scenario's corridor walls (shapely's own coordinates)
    from avblocks.scenarios.targets import load_any
    world = load_any("formation", {}, None)[3]["obstacles"]
    (wmsg,) = msgs["/sim/world"]
    rings = [np.array([[p.x, p.y] for p in e.lines[0].points]) for e in wmsg.value.entities]
    assert len(rings) == len(world.geoms) == 2
    for ring, geom in zip(rings, world.geoms):
        want = {tuple(np.round(c, 9)) for c in np.asarray(geom.exterior.coords)}
        assert {tuple(np.round(c, 9)) for c in ring} == want
    # links: the leader tree of the LeaderFollower block, between the agents' positions
    leader = load_any("formation", {}, None)[0]["lf"].block.leader
    pairs = [(i, int(leader[i])) for i in range(n) if leader[i] >= 0]
    last = msgs["/sim/links"][-1].value.entities[0].lines[0].points
    got = np.array([[p.x, p.y] for p in last]).reshape(-1, 2, 2)
    want = np.array([[pose[-1, a, :2], pose[-1, b, :2]] for a, b in pairs])
    np.testing.assert_allclose(got, want, atol=1e-12)
    # every signal, every sample, values as logged (labelled components by name)
    err = res["lf.error"]
    sig = msgs["/sim/signals/lf.error"]
    assert [m.log_time for m in sig] == list(_ns(res.t))
    got = np.array([[[a["l"], a["alpha"]] for a in m.value["agents"]] for m in sig])
    np.testing.assert_array_equal(got, err)
    np.testing.assert_array_equal([m.value["t"] for m in sig], res.t)
    mode = msgs["/sim/signals/supervisor.mode"]
    np.testing.assert_array_equal([m.value["value"] for m in mode], res["supervisor.mode"])
    hit = msgs["/sim/signals/collision.hit_agent"]
    np.testing.assert_array_equal([m.value["agents"] for m in hit], res["collision.hit_agent"])
    # the outcome line, at the last sample
    (log,) = msgs["/sim/log"]
    assert log.value.message == f"outcome: {summary['outcome']}"
    assert log.log_time == _ns(res.t[-1])
    assert meta["avblocks"]["prefix"] == "sim"


def quadrotor_run():
    n = 3
    d = av.Diagram()
    fleet = d.add(av.vehicles.velocity_controlled_quadrotor(
        av.vehicles.Quadrotor(np.column_stack([np.arange(n), np.zeros(n), np.ones(n)]))),
        name="fleet")
    go = d.add(av.blocks.Constant(np.tile([0.5, 0.2, 0.1], (n, 1))), name="go")
    d.connect(go.y, fleet.velocity)
    return av.simulate(d, 1.0, dt=0.01, log=[fleet.position, fleet.attitude], log_every=10)


def test_3d_poses_use_the_attitude_and_the_names_the_run_logged_by(tmp_path):
    res = quadrotor_run()
    # a subsystem's signals keep the names they were logged by across save/load
    res = av.Results.load(res.save(tmp_path / "r.nc"))
    assert "fleet.position" in res and res.aliases["fleet.position"] == "fleet.quad.position"
    p = res.to_mcap(tmp_path / "q.mcap", every=3)
    msgs, _summ, _meta = read(p)
    idx = [0, 3, 6, 9, 10]                         # every 3rd sample and the last
    tf = msgs["/sim/tf"]
    assert [m.log_time for m in tf] == list(_ns(res.t[idx]))
    pos, att = res["fleet.position"], res["fleet.attitude"]
    for m, j in zip(tf, idx):
        trs = m.value.transforms
        assert [tr.child_frame_id for tr in trs] == ["sim/fleet/0", "sim/fleet/1",
                                                     "sim/fleet/2"]
        np.testing.assert_allclose([[tr.translation.x, tr.translation.y, tr.translation.z]
                                    for tr in trs], pos[j], atol=1e-12)
        q = att[j] / np.linalg.norm(att[j], axis=1, keepdims=True)
        np.testing.assert_allclose([[tr.rotation.w, tr.rotation.x, tr.rotation.y,
                                     tr.rotation.z] for tr in trs], q, atol=1e-12)
    assert "/sim/signals/fleet.position" in msgs
    got = np.array([[[a["x"], a["y"], a["z"]] for a in m.value["agents"]]
                    for m in msgs["/sim/signals/fleet.position"]])
    np.testing.assert_array_equal(got, pos[idx])
    # a start time moves every message
    p2 = res.to_mcap(tmp_path / "q2.mcap", start=1_700_000_000.0, prefix="run2")
    msgs2, _s, _m = read(p2)
    assert msgs2["/run2/tf"][0].log_time == 1_700_000_000 * 10**9


def test_bad_requests_are_errors_naming_the_problem(tmp_path):
    res = quadrotor_run()
    with pytest.raises(ParameterError, match="ends in .mcap"):
        res.to_mcap(tmp_path / "run.bag")
    with pytest.raises(ParameterError, match="prefix"):
        res.to_mcap(tmp_path / "run.mcap", prefix="a/b")
    with pytest.raises(AvError, match="no folder"):
        res.to_mcap(tmp_path / "nowhere" / "run.mcap")
    with pytest.raises(ParameterError, match="every"):
        res.to_mcap(tmp_path / "run.mcap", every=0)
    ens = av.Results(res.t, {k: np.stack([v, v]) for k, v in res.data.items()}, runs=2)
    with pytest.raises(ParameterError, match="one run"):
        ens.to_mcap(tmp_path / "run.mcap")
    with pytest.raises(TypeError):
        res.to_mcap(tmp_path / "run.mcap", colour="red")
    assert not list(tmp_path.glob("*.mcap")) and not list(tmp_path.glob(".*part"))
    # the command: a folder without results
    (tmp_path / "empty").mkdir()
    assert main(["export", str(tmp_path / "empty"), "--mcap"]) == 2


def test_flight_logs_are_read_as_data_within_limits(tmp_path):
    from avblocks.foxglove import read_flight_log
    good = {"wall": 10.0, "ev": "cmd", "t": 0.5, "v": [[0.1, 0.2, 0.0]]}
    cases = {
        "not json": "{oops\n",
        "no event": json.dumps({"wall": 1.0}) + "\n",
        "wall is text": json.dumps({"wall": "x", "ev": "start"}) + "\n",
        "bad set-point": json.dumps({**good, "v": [[0.1, "a", 0.0]]}) + "\n",
        "ragged set-points": json.dumps(good) + "\n" + json.dumps(
            {**good, "v": [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]}) + "\n",
        "deep": json.dumps({"wall": 1.0, "ev": "x", "a": [[[[[[[[[[[[[[[[[[1]]]]]]]]]]]]]]]]]]})
                + "\n",
    }
    for why, text in cases.items():
        p = tmp_path / "log.jsonl"
        p.write_text(text)
        with pytest.raises(AvError):
            read_flight_log(p)
            pytest.fail(f"accepted a flight log with {why}")
    p.write_text("x" * 100 + "\n")
    with pytest.raises(AvError, match="too large"):
        read_flight_log(p, max_bytes=50)
    with pytest.raises(AvError, match="not a regular file"):
        read_flight_log(tmp_path)
    p.write_text(json.dumps(good) + "\n\n" + json.dumps({**good, "t": 0.6, "wall": 10.1}))
    log = read_flight_log(p)
    np.testing.assert_array_equal(log.t, [0.5, 0.6])
    assert log.setpoints.shape == (2, 1, 3) and log.wall_offset == pytest.approx(9.5)


def test_the_shipped_layout_is_current_and_plots_topics_the_writer_makes(tmp_path):
    from avblocks.foxglove import LAYOUT_FILE, layout_json
    assert LAYOUT_FILE.read_text() == layout_json()
    layout = json.loads(LAYOUT_FILE.read_text())
    text = json.dumps(layout)
    res = quadrotor_run()
    msgs, _s, _m = read(res.to_mcap(tmp_path / "q.mcap"))
    # the plotted message paths resolve in a written run
    for path in ("/sim/signals/fleet.position.agents[0].x",
                 "/sim/signals/fleet.position.agents[1].z"):
        assert path in text
        topic, field = path.split(".agents")
        value = msgs[topic][0].value
        i = int(field[1])
        assert isinstance(value["agents"][i][field[-1]], float)
    for topic in ("/sim/bodies", "/flight/setpoint_arrows", "/flight/bodies"):
        assert topic in text
