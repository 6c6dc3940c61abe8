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
