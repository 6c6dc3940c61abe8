"""``avblocks edit`` as a user starts it: a process, its printed URL, Ctrl-C."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import urllib.error
import urllib.request
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[2] / "src"


def _start(args, cwd):
    path = os.pathsep.join(x for x in (str(SRC), os.environ.get("PYTHONPATH")) if x)
    env = {**os.environ, "PYTHONPATH": path,
           "BROWSER": "true"}
    p = subprocess.Popen([sys.executable, "-m", "avblocks", "edit", *args], cwd=cwd,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    line = p.stdout.readline()
    return p, line


def test_edit_prints_a_tokened_url_and_stops_on_ctrl_c(tmp_path, need_editor_extra):
    need_editor_extra("starlette", "uvicorn")
    (tmp_path / "mine.yaml").write_text((SRC / "avblocks/scenarios/swap.yaml").read_text())
    p, line = _start(["mine.yaml", "--no-browser"], tmp_path)
    try:
        m = re.match(r"avblocks editor: (http://127\.0\.0\.1:(\d+)/([\w-]+)/)$", line.strip())
        assert m, line
        url, port, token = m.group(1), m.group(2), m.group(3)
        assert len(token) >= 24
        with urllib.request.urlopen(url + "api/files", timeout=30) as r:
            files = json.loads(r.read())
        assert files["initial"] == {"path": "mine.yaml"}
        assert files["root"] == str(tmp_path.resolve())
        with pytest.raises(urllib.error.HTTPError) as e:
            urllib.request.urlopen(f"http://127.0.0.1:{port}/api/files", timeout=30)
        assert e.value.code == 403
    finally:
        p.send_signal(signal.SIGINT)
        out, err = p.communicate(timeout=30)
    assert p.returncode == 0, err
    assert "Traceback" not in err and "stopped" in err


def test_edit_opens_a_file_in_another_folder_and_works_there(tmp_path, need_editor_extra):
    """``avblocks edit ../x.yaml`` opens it (no need to cd first): the editor's
    folder is that file's own, and the confinement holds there (a file
    beside that folder's parent is refused, by the server's own check)."""
    need_editor_extra("starlette", "uvicorn")
    work = tmp_path / "work"
    inner = tmp_path / "elsewhere"
    work.mkdir()
    inner.mkdir()
    (work / "x.yaml").write_text((SRC / "avblocks/scenarios/swap.yaml").read_text())
    (tmp_path / "secret.yaml").write_text("name: secret\n")
    p, line = _start(["../work/x.yaml", "--no-browser"], inner)
    try:
        m = re.match(r"avblocks editor: (http://127\.0\.0\.1:\d+/[\w-]+/)$", line.strip())
        assert m, line
        url = m.group(1)
        with urllib.request.urlopen(url + "api/files", timeout=30) as r:
            files = json.loads(r.read())
        assert files["root"] == str(work.resolve())
        assert files["initial"] == {"path": "x.yaml"}
        assert [f["path"] for f in files["files"]] == ["x.yaml"]
        req = urllib.request.Request(url + "api/load", method="POST",
                                     data=json.dumps({"path": "x.yaml"}).encode(),
                                     headers={"content-type": "application/json"})
        with urllib.request.urlopen(req, timeout=30) as r:
            assert json.loads(r.read())["document"]["name"] == "swap"
        req = urllib.request.Request(url + "api/load", method="POST",
                                     data=json.dumps({"path": "../secret.yaml"}).encode(),
                                     headers={"content-type": "application/json"})
        with pytest.raises(urllib.error.HTTPError) as e:
            urllib.request.urlopen(req, timeout=30)
        assert e.value.code == 400
        assert json.loads(e.value.read())["error"]["kind"] == "OutsideFolder"
    finally:
        p.send_signal(signal.SIGINT)
        out, err = p.communicate(timeout=30)
    assert p.returncode == 0, err


def test_edit_of_a_name_that_is_neither_a_file_nor_a_case_study(tmp_path, need_editor_extra):
    need_editor_extra("starlette", "uvicorn")
    r = subprocess.run([sys.executable, "-m", "avblocks", "edit", "../nothing.yaml",
                        "--no-browser"], cwd=tmp_path, capture_output=True, text=True,
                       env={**os.environ, "PYTHONPATH": str(SRC)}, timeout=60)
    assert r.returncode == 2
    assert "no scenario file or built-in case study '../nothing.yaml'" in r.stderr


def test_a_missing_extra_names_the_install_command(tmp_path):
    code = ("import sys; sys.modules['uvicorn'] = None\n"
            "from avblocks.cli import main\n"
            "sys.exit(main(['edit', '--no-browser']))\n")
    r = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True,
                       text=True, env={**os.environ, "PYTHONPATH": str(SRC)}, timeout=60)
    assert r.returncode == 2
    assert 'pip install "avblocks[editor]"' in r.stderr
    assert "Traceback" not in r.stderr
    code = ("import sys; sys.modules['anywidget'] = None\n"
            "import avblocks as av\n"
            "try:\n    av.edit()\nexcept av.AvError as e:\n    print(e)\n")
    r = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True,
                       text=True, env={**os.environ, "PYTHONPATH": str(SRC)}, timeout=60)
    assert 'pip install "avblocks[editor]"' in r.stdout, r.stderr
