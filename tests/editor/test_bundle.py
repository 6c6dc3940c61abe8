"""The shipped front end (``src/avblocks/editor/static``) is what its sources
build: ``npm ci && npm run build`` of a copy of ``web/`` into a temporary
folder gives the same files, byte for byte (CI fails when a source changed
and the bundle was not rebuilt)."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

EDITOR = Path(__file__).resolve().parents[2] / "src" / "avblocks" / "editor"

pytestmark = [pytest.mark.editor, pytest.mark.slow]


def _files(root: Path) -> dict[str, bytes]:
    return {p.relative_to(root).as_posix(): p.read_bytes()
            for p in sorted(root.rglob("*")) if p.is_file()}


def test_shipped_bundle_is_what_the_sources_build(tmp_path):
    npm = shutil.which("npm")
    if npm is None:
        if os.environ.get("CI"):
            pytest.fail("CI builds the editor's front end: npm is needed")
        pytest.skip("needs npm (Node.js) to build the front end")
    web = tmp_path / "web"
    shutil.copytree(EDITOR / "web", web, ignore=shutil.ignore_patterns("node_modules"))
    # the build writes ../static next to the copy, as in the repository
    env = {**os.environ, "CI": "1", "npm_config_fund": "false", "npm_config_audit": "false"}
    subprocess.run([npm, "ci", "--no-audit", "--no-fund"], cwd=web, check=True, env=env,
                   capture_output=True, timeout=900)
    r = subprocess.run([npm, "run", "build"], cwd=web, env=env, capture_output=True,
                       text=True, timeout=900)
    assert r.returncode == 0, r.stdout[-4000:] + r.stderr[-4000:]
    built = _files(tmp_path / "static")
    shipped = _files(EDITOR / "static")
    assert sorted(built) == sorted(shipped), "rebuild: cd src/avblocks/editor/web && npm run build"
    differ = [name for name in built if built[name] != shipped[name]]
    assert not differ, f"{differ} differ from the sources' build: npm run build, and commit static/"
    assert "index.html" in built and "widget.js" in built
