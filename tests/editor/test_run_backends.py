"""Runs on the compiled JAX engine and the live view from the editor."""

from __future__ import annotations

import time
import urllib.error
import urllib.request

import numpy as np
import pytest


def _wait(srv, rid, timeout=300):
    t_end = time.monotonic() + timeout
    while True:
        status, st = srv.get(f"run/{rid}")
        if st["status"] != "running" or time.monotonic() > t_end:
            return st
        time.sleep(0.1)


@pytest.mark.jax
def test_jax_run_gives_the_numpy_runs_signals(editor_server):
    pytest.importorskip("jax")
    status, loaded = editor_server.post("load", {"builtin": "nest"})
    doc = loaded["document"]
    runs = {}
    for backend in ("numpy", "jax"):
        status, body = editor_server.post("run", {"document": doc, "backend": backend,
                                                  "t_final": 2})
        assert status == 200, body
        st = _wait(editor_server, body["run"])
        assert st["status"] == "done", st
        assert st["progress"] == 1.0
        status, sig = editor_server.get(f"run/{body['run']}/signal?name=bees.pose")
        runs[backend] = (st, np.asarray(sig["values"]))
    (st_np, pose_np), (st_jax, pose_jax) = runs["numpy"], runs["jax"]
    np.testing.assert_allclose(pose_jax, pose_np, atol=1e-9)
    assert st_jax["outcome"] == st_np["outcome"]


def test_live_opens_the_drawn_diagram_in_the_live_view(editor_server):
    pytest.importorskip("viser")
    status, loaded = editor_server.post("load", {"builtin": "swap"})
    status, body = editor_server.post("live", {"document": loaded["document"]})
    assert status == 200, body
    url = body["url"]
    assert url.startswith("http://127.0.0.1:") and url.endswith("/")
    with urllib.request.urlopen(url, timeout=30) as r:          # the viser page
        assert r.status == 200 and b"<html" in r.read().lower()
    token = url.rstrip("/").rsplit("/", 1)[1]
    with pytest.raises(urllib.error.HTTPError) as e:
        urllib.request.urlopen(url.replace(token, "wrong"), timeout=30)
    assert e.value.code == 403
    view = editor_server.server.service._lives[-1]
    view.stop()
    assert view.wait(30) is not None          # the run ended when told to


@pytest.mark.jax
def test_a_jax_run_reports_progress_and_can_be_cancelled(editor_server):
    """The compiled run goes in segments (core.compiled.segments): a poll sees
    it part-way, and a cancel ends it ``cancelled`` with the samples so far."""
    pytest.importorskip("jax")
    status, loaded = editor_server.post("load", {"builtin": "nest"})
    status, body = editor_server.post("run", {"document": loaded["document"],
                                              "backend": "jax", "t_final": 400})
    assert status == 200, body
    rid = body["run"]
    seen = []
    t_end = time.monotonic() + 300
    while time.monotonic() < t_end:
        status, st = editor_server.get(f"run/{rid}")
        seen.append(st["progress"])
        if st["status"] != "running" or 0 < st["progress"] < 1:
            break
        time.sleep(0.02)
    assert st["status"] == "running" and 0 < st["progress"] < 1, st
    status, _ = editor_server.post(f"run/{rid}/cancel")
    assert status == 200
    st = _wait(editor_server, rid, timeout=120)
    assert st["status"] == "cancelled", st
    assert seen == sorted(seen)                     # progress never goes back
    assert 0 < st["progress"] < 1 and 0 < st["t"] < 400
    # the samples logged up to the stop came back: a wire can be plotted
    status, sig = editor_server.get(f"run/{rid}/signal?name=bees.pose")
    assert status == 200 and sig["t"][-1] == pytest.approx(st["t"])
