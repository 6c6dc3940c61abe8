"""The documentation site: it builds with ``--strict`` (no broken link, no
unresolved reference, no docstring griffe cannot parse), its API reference
holds every public name, and the tutorials that are also notebooks run in
Jupyter."""

from __future__ import annotations

import importlib
import importlib.util
import pkgutil
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


def _gen_api():
    spec = importlib.util.spec_from_file_location("gen_api", DOCS / "gen_api.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _needs(module):
    if importlib.util.find_spec(module) is None:
        pytest.skip(f"needs {module} (pip install -e '.[docs]')")


def test_api_pages_are_current():
    assert _gen_api().main(check=True) == 0, "run python docs/gen_api.py"


def test_every_public_package_has_an_api_page():
    import avblocks
    listed = {pkg for _, pkg, _ in _gen_api().PAGES}
    missing = []
    for info in pkgutil.walk_packages(avblocks.__path__, "avblocks."):
        if not info.ispkg:
            continue
        name = info.name
        if any(part.startswith("_") for part in name.split(".")):
            continue
        mod = importlib.import_module(name)
        if getattr(mod, "__all__", None) and _gen_api().public_names(name) \
                and name not in listed:
            missing.append(name)
    assert not missing, f"packages with public names but no API page: {missing}"


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    _needs("mkdocs")
    _needs("material")
    _needs("mkdocstrings_handlers.python")
    out = tmp_path_factory.mktemp("site")
    # the README's command as written (no -q: strict mode counts warnings that
    # -q would hide from this test); only the output folder differs
    r = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict",
                        "-f", str(ROOT / "mkdocs.yml"), "-d", str(out)],
                       cwd=ROOT, capture_output=True, text=True, timeout=600)
    warnings = log_problems(r.stdout + r.stderr)
    print("\n".join(warnings))
    assert r.returncode == 0 and not warnings, (
        f"mkdocs build --strict: exit {r.returncode}, {len(warnings)} warning(s):\n"
        + "\n".join(warnings[:60]))
    return out


_ANSI = re.compile(r"\x1b\[[0-9;]*m")


def log_problems(text):
    """The WARNING and ERROR lines of a MkDocs log (colour codes removed)."""
    lines = (_ANSI.sub("", ln).strip() for ln in text.splitlines())
    return [ln for ln in lines if re.match(r"(WARNING|ERROR)\b", ln)]


def test_log_problems_counts_every_warning():
    log = ("\x1b[33mWARNING\x1b[0m -  griffe: a.py:1: Could not parse line 'x'\n"
           "INFO    -  Cleaning site directory\n"
           "  To disable this warning, set NO_MKDOCS_2_WARNING=1.\n"
           "WARNING -  mkdocs_autorefs: api/x.md: Could not find cross-reference target\n"
           "ERROR   -  Config value 'nav': bad\n")
    assert log_problems(log) == [
        "WARNING -  griffe: a.py:1: Could not parse line 'x'",
        "WARNING -  mkdocs_autorefs: api/x.md: Could not find cross-reference target",
        "ERROR   -  Config value 'nav': bad"]


def test_site_builds_strict_and_works_offline(site):
    index = (site / "index.html").read_text()
    assert "fonts.googleapis.com" not in index
    # every script and stylesheet is local
    for src in re.findall(r'(?:src|href)="(https?://[^"]+\.(?:js|css))"', index):
        raise AssertionError(f"the site loads {src} from outside")
    for page in ["getting-started", "tutorial-diagram", "gallery", "benchmarks",
                 "api/index", "changelog"]:
        assert (site / f"{page}.html").is_file(), page


def test_api_reference_renders_every_public_name(site):
    gen = _gen_api()
    page_of = {package: page for page, package, _ in gen.PAGES}
    missing = []
    for page, package, _ in gen.PAGES:
        html = (site / "api" / f"{page}.html").read_text()
        for name in gen.public_names(package):
            home = gen.home_of(package, name) if package == "avblocks" else None
            target = f"{home or package}.{name}"
            if home is None and f'id="{target}"' not in html:
                missing.append(target)
            elif home is not None and f'href="{page_of[home]}.html#{target}"' not in html:
                missing.append(f"{package}.{name} (link to {target})")
    assert not missing, f"not in the rendered reference: {missing}"


def test_changelog_matches_the_package_version():
    import avblocks
    text = (ROOT / "CHANGELOG.md").read_text()
    versions = re.findall(r"^## \[(\d+\.\d+\.\d+)\]", text, flags=re.M)
    assert versions and versions[0] == avblocks.__version__
    toml = (ROOT / "pyproject.toml").read_text()
    assert f'version = "{avblocks.__version__}"' in toml


def test_version_flag():
    exe = shutil.which("avblocks", path=str(Path(sys.executable).parent))
    cmd = [exe] if exe else [sys.executable, "-m", "avblocks"]
    r = subprocess.run(cmd + ["--version"], capture_output=True, text=True, timeout=60)
    import avblocks
    assert r.returncode == 0 and avblocks.__version__ in r.stdout + r.stderr


def _notebooks():
    spec = importlib.util.spec_from_file_location("notebooks", DOCS / "notebooks.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("page", _notebooks().PAGES)
def test_tutorial_notebooks_execute(page, tmp_path, monkeypatch):
    """The tutorials that are also notebooks (``python docs/notebooks.py``
    writes them) run in a Jupyter kernel top to bottom and print what the
    page says they print."""
    # small sizes, as the examples' test (lab 7's page loads a trained policy)
    monkeypatch.setenv("AVBLOCKS_EXAMPLE_SMALL", "1")
    _needs("jupytext")
    _needs("nbclient")
    _needs("ipykernel")
    import nbclient
    nb = _notebooks().notebook(page)
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert len(code) >= 1 and not any(c.source.startswith("%%") for c in code)
    client = nbclient.NotebookClient(nb, timeout=300, kernel_name="python3",
                                     resources={"metadata": {"path": str(tmp_path)}})
    client.execute()
    outputs = [o for c in code for o in c.get("outputs", [])]
    assert not [o for o in outputs if o.get("output_type") == "error"]
    text = "\n".join(o.get("text", "") for o in outputs)
    expected = {"getting-started.md": "(1201, 20, 3)", "tutorial-diagram.md": "0.134 0.134",
                "tutorial-scale.md": "N =  30000",
                # the labs: what each page's diagram measures
                "labs/lab1.md": "rk4  : error after 10 s at dt = 0.1 s: 5.2e-09 m; order 4.0",
                "labs/lab2.md": "d = 0.10 m: largest |omega|   10.0 rad/s",
                "labs/lab3.md": "K = 2.0: distance error decays at 2.000 /s",
                "labs/lab4.md": "N = 12: measured rate 0.2679 /s, K lambda_2 = 0.2679 /s",
                "labs/lab5.md": ("through the safety filter : closest pair 0.728 m",
                                 "flock of 12: order parameter 0.99990, closest pair 0.866 m "
                                 "at 20 s (0.406 m over the run)"),
                "labs/lab6.md": "'tb2', 'stale')]",
                "labs/lab7.md": ("hand-written controller: 69.3% of the agents at their goal "
                                 "without contact over the check's 50 fixed held-out episodes",
                                 "the policy as a block: 91.3% of the agents at their goal"),
                "labs/lab8.md": ("dead reckoning: RMS position error 0.96 m after 30 s",
                                 "assuming a quarter of it: average NEES 15.82, within the 99 % "
                                 "bounds at 0% of the steps"),
                }[page]
    for line in (expected,) if isinstance(expected, str) else expected:
        assert line in text


def _make_images():
    spec = importlib.util.spec_from_file_location("make_images", DOCS / "make_images.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_every_picture_is_made_by_the_images_script_and_named_by_a_page():
    problems = _make_images().check()
    assert not problems, "\n".join(problems)


def test_the_images_script_draws_a_picture(tmp_path, monkeypatch):
    import matplotlib.pyplot as plt
    mi = _make_images()
    monkeypatch.setattr(mi, "IMAGES", tmp_path)
    mi.produce(["diagram", "animation_frame"])
    plt.close("all")
    for name in ("diagram", "animation_frame"):
        head = (tmp_path / f"{name}.png").read_bytes()[:8]
        assert head == b"\x89PNG\r\n\x1a\n"
