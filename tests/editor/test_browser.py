"""The editor in a real browser: the system Chromium driven by Playwright
against the real server (``editor_server``), as a user would use it.

Truth the page is checked against: the server's own answers computed
independently in Python (``validate`` of the same document gives the
library's error message the page must show on the port), the scenario files
on disk, and ``avblocks run`` of the saved file against the built-in
original (same ``summary.json``).

The screenshots of ``docs/editor.md`` are written here
(``docs/images/editor-*.png``).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = [pytest.mark.editor]

CHROMIUM = "/usr/bin/chromium"
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
        "--disable-component-update", "--disable-sync", "--no-first-run"]
DOCS_IMAGES = Path(__file__).resolve().parents[2] / "docs" / "images"
STATIC = Path(__file__).resolve().parents[2] / "src" / "avblocks" / "editor" / "static"


def _need_browser():
    missing = []
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        missing.append("playwright (pip)")
    if not Path(CHROMIUM).exists():
        missing.append(CHROMIUM)
    if not (STATIC / "index.html").is_file():
        missing.append("the built front end (editor/static)")
    if missing:
        if os.environ.get("CI"):
            pytest.fail(f"the browser tests need {missing} in CI")
        pytest.skip(f"needs {missing}")


@pytest.fixture(scope="module")
def browser():
    _need_browser()
    from playwright.sync_api import sync_playwright
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        try:
            yield b
        finally:
            b.close()


@pytest.fixture
def page(browser, editor_server):
    # bypass_csp: Playwright's string predicates (wait_for_function) are eval'd
    # in the page, which the server's CSP forbids; test_server_headers.py
    # checks the page under its CSP
    ctx = browser.new_context(viewport={"width": 1440, "height": 880}, accept_downloads=True,
                              bypass_csp=True)
    pg = ctx.new_page()
    errors = []
    pg.on("pageerror", lambda e: errors.append(str(e)))
    # nothing may be loaded from outside the server
    outside = []
    pg.on("request", lambda r: outside.append(r.url) if not r.url.startswith(
        (editor_server.base, "data:", "blob:")) else None)
    pg.goto(editor_server.url)
    pg.wait_for_selector(".palette-item")
    yield pg
    ctx.close()
    assert not errors, errors
    assert not outside, outside


def shot(pg, name):
    DOCS_IMAGES.mkdir(parents=True, exist_ok=True)
    pg.wait_for_timeout(250)
    pg.screenshot(path=str(DOCS_IMAGES / f"editor-{name}.png"))


def wait_checked(pg):
    """Wait until the check shown is the answer about the document as it is now."""
    pg.wait_for_function("document.querySelector('[data-testid=check]')?.dataset.fresh === 'true'",
                         timeout=60_000)


def drag_from_palette(pg, type_, x, y):
    item = pg.locator(f'.palette-item[data-type="{type_}"]')
    item.scroll_into_view_if_needed()
    item.drag_to(pg.locator(".react-flow__pane"), target_position={"x": x, "y": y})


def handle(pg, block, port, side):
    kind = "source" if side == "out" else "target"
    return pg.locator(f'.react-flow__node[data-id="{block}"] '
                      f'.react-flow__handle.{kind}[data-handleid="{port}"]')


def wire(pg, src, dst):
    """Drag a wire from output ``src`` to input ``dst`` ("block.port") and wait
    for it on the canvas. A block that has just been added may not have its
    handles measured yet (React Flow measures them after the first paint): then
    the first drag misses, as a user's hurried one would, and is drawn again."""
    sb, sp = src.split(".")
    db, dp = dst.split(".")
    for _ in range(3):
        pg.wait_for_timeout(150)
        a = handle(pg, sb, sp, "out").bounding_box()
        b = handle(pg, db, dp, "in").bounding_box()
        pg.mouse.move(a["x"] + a["width"] / 2, a["y"] + a["height"] / 2)
        pg.mouse.down()
        pg.mouse.move((a["x"] + b["x"]) / 2, (a["y"] + b["y"]) / 2 + 20, steps=6)
        pg.mouse.move(b["x"] + b["width"] / 2, b["y"] + b["height"] / 2, steps=6)
        pg.mouse.up()
        if until(lambda: pg.locator(f'.react-flow__edge[data-id="{src}->{dst}"]').count() == 1,
                 timeout=3.0):
            return
    raise AssertionError(f"could not draw the wire {src} -> {dst}")


def wait_edge(pg, wire_id):
    """Wait for the wire ``"a.x->b.y"`` to be on the canvas."""
    pg.wait_for_selector(f'.react-flow__edge[data-id="{wire_id}"]', state="attached")


def click_empty(pg):
    """Click the canvas where nothing is drawn (clears the selection)."""
    box = pg.locator(".react-flow__pane").bounding_box()
    pg.locator(".react-flow__pane").click(position={"x": box["width"] / 2, "y": 20})


def until(check, timeout=10.0):
    """Poll ``check`` until it holds (the page re-renders asynchronously)."""
    t0 = time.monotonic()
    while True:
        ok = check()
        if ok or time.monotonic() - t0 > timeout:
            return ok
        time.sleep(0.05)


ALL_IN_VIEW = """n => {
  const p = document.querySelector('.react-flow__pane').getBoundingClientRect();
  const ns = [...document.querySelectorAll('.react-flow__node-block')];
  return ns.length >= n && ns.every(e => { const r = e.getBoundingClientRect();
    return r.left >= p.left && r.right <= p.right - 10 && r.top >= p.top
      && r.bottom <= p.bottom; }); }"""


VIEWPORT = "document.querySelector('.react-flow__viewport').style.transform"


def show_everything(pg, n_blocks):
    """Zoom out (the zoom buttons) until all ``n_blocks`` blocks are drawn, inside the
    canvas (each click waited for: on a loaded machine the page takes its time)."""
    for _ in range(20):
        if pg.evaluate(ALL_IN_VIEW, n_blocks):
            break
        before = pg.evaluate(VIEWPORT)
        pg.locator(".react-flow__controls-zoomout").click()
        pg.wait_for_function(f"t => {VIEWPORT} !== t", arg=before, timeout=10_000)
        pg.wait_for_timeout(100)
    pg.wait_for_function(ALL_IN_VIEW, arg=n_blocks, timeout=10_000)
    assert pg.locator(".react-flow__node-block").count() == n_blocks


def blocks_on_canvas(pg):
    return sorted(pg.eval_on_selector_all(".react-flow__node-block",
                                          "ns => ns.map(n => n.dataset.id)"))


def current_document(pg, editor_server, name):
    """The document as the page holds it, read back from a saved file."""
    pg.keyboard.press("Escape")
    pg.keyboard.press("Control+Shift+S")
    pg.get_by_label("File path").fill(name)
    pg.get_by_test_id("saveas-ok").click()
    pg.wait_for_selector(".modal", state="detached")
    path = editor_server.root / name
    for _ in range(50):
        if path.is_file():
            break
        time.sleep(0.1)
    status, loaded = editor_server.post("load", {"path": name})
    assert status == 200, loaded
    return loaded["document"]


def test_403_without_the_token(browser, editor_server):
    _need_browser()
    ctx = browser.new_context()
    pg = ctx.new_page()
    r = pg.goto(editor_server.base)
    assert r.status == 403
    r = pg.goto(editor_server.base + "api/palette")
    assert r.status == 403
    r = pg.goto(editor_server.base + "x" + editor_server.token + "/")
    assert r.status == 403
    r = pg.goto(editor_server.url)
    assert r.status == 200
    ctx.close()


def test_draw_wire_set_agents_run(page, editor_server):
    pg = page
    shot(pg, "empty")
    drag_from_palette(pg, "vehicles.Unicycle", 260, 260)
    drag_from_palette(pg, "controllers.PointToPoint", 620, 260)
    pg.wait_for_selector('.react-flow__node[data-id="point_to_point"]')
    assert blocks_on_canvas(pg) == ["point_to_point", "unicycle"]

    # both wires, each way
    wire(pg, "unicycle.pose", "point_to_point.pose")
    wire(pg, "point_to_point.cmd", "unicycle.cmd")
    wait_edge(pg, "unicycle.pose->point_to_point.pose")
    wait_edge(pg, "point_to_point.cmd->unicycle.cmd")
    wait_checked(pg)

    # the diagram parameters: agents 15 -> 300 in one field
    click_empty(pg)
    agents = pg.get_by_test_id("dparam-agents")
    agents.fill("300")
    wait_checked(pg)

    doc = current_document(pg, editor_server, "drawn.yaml")
    assert doc["parameters"]["agents"] == 300
    assert sorted(map(tuple, doc["wires"])) == [("point_to_point.cmd", "unicycle.cmd"),
                                                ("unicycle.pose", "point_to_point.pose")]
    assert {b: v["type"] for b, v in doc["blocks"].items()} == {
        "unicycle": "vehicles.Unicycle", "point_to_point": "controllers.PointToPoint"}

    # the server's own check of what the page drew: it builds, and the wire
    # labels are the signal shapes it reports (300 agents)
    status, v = editor_server.post("validate", {"document": doc})
    assert status == 200 and v["ok"], v["errors"]
    assert pg.get_by_test_id("check").inner_text().startswith("✓")
    label = pg.locator('[data-wire="unicycle.pose->point_to_point.pose"]').inner_text()
    assert label == v["signals"]["unicycle.pose"]["shape"]
    assert "300" in label
    shot(pg, "wired")

    # run a short simulation in the page
    pg.get_by_label("t_final").fill("2")
    pg.get_by_test_id("run").click()
    outcome = pg.get_by_test_id("outcome")
    outcome.wait_for(timeout=120_000)
    assert outcome.inner_text().strip()
    pg.locator(".run-state.done").wait_for(timeout=120_000)
    # after the run, a click on a wire plots its signal
    pg.locator('[data-wire="unicycle.pose->point_to_point.pose"]').click()
    pg.get_by_test_id("signal-plot").wait_for(timeout=30_000)
    # (300, 3): one agent's x, y and heading
    assert pg.locator('[data-testid="signal-plot"] path').count() == 3
    shot(pg, "run")


def test_wrong_wire_shows_the_library_error_on_the_port(page, editor_server):
    pg = page
    drag_from_palette(pg, "vehicles.Unicycle", 260, 260)
    drag_from_palette(pg, "controllers.PointToPoint", 620, 260)
    pg.wait_for_selector('.react-flow__node[data-id="point_to_point"]')
    wire(pg, "unicycle.pose", "point_to_point.pose")
    # a pose (N, 3) into the unicycle's command input (N, 2)
    wire(pg, "unicycle.pose", "unicycle.cmd")
    wait_edge(pg, "unicycle.pose->unicycle.cmd")
    wait_checked(pg)
    bad = pg.locator('.react-flow__node[data-id="unicycle"] '
                     '.react-flow__handle.target.bad[data-handleid="cmd"]')
    bad.wait_for()

    # what the library says about this diagram, asked independently
    doc = current_document(pg, editor_server, "wrong.yaml")
    status, v = editor_server.post("validate", {"document": doc})
    assert status == 200 and not v["ok"]
    on_port = [e["message"] for e in v["errors"]
               if e.get("block") == "unicycle" and e.get("port") == "cmd"]
    assert on_port, v["errors"]
    title = bad.get_attribute("title")
    for m in on_port:
        assert m in title
    # the Problems list shows it too, and a click selects the block
    pg.get_by_test_id("tab-problems").click()
    prob = pg.locator(".problem", has_text=on_port[0])
    prob.first.click()
    assert until(lambda: pg.locator('.react-flow__node[data-id="unicycle"].selected').count() == 1)
    pg.keyboard.press("f")  # fit the view
    pg.wait_for_timeout(400)
    shot(pg, "error")

    # one driver per input: a wire into the taken input replaces the old one
    wire(pg, "point_to_point.cmd", "unicycle.cmd")
    wait_edge(pg, "point_to_point.cmd->unicycle.cmd")
    assert pg.locator('.react-flow__edge[data-id="unicycle.pose->unicycle.cmd"]').count() == 0
    assert "one driver" in pg.get_by_test_id("toast").last.inner_text()
    wait_checked(pg)
    assert pg.get_by_test_id("check").inner_text().startswith("✓")


def test_undo_redo(page):
    pg = page
    drag_from_palette(pg, "vehicles.Unicycle", 260, 260)
    drag_from_palette(pg, "controllers.PointToPoint", 620, 260)
    pg.wait_for_selector('.react-flow__node[data-id="point_to_point"]')
    wire(pg, "unicycle.pose", "point_to_point.pose")
    pg.wait_for_selector(".react-flow__edge", state="attached")
    click_empty(pg)
    pg.keyboard.press("Control+z")
    assert until(lambda: pg.locator(".react-flow__edge").count() == 0)
    pg.keyboard.press("Control+z")
    assert until(lambda: blocks_on_canvas(pg) == ["unicycle"])
    pg.keyboard.press("Control+Shift+z")
    assert until(lambda: blocks_on_canvas(pg) == ["point_to_point", "unicycle"])
    pg.keyboard.press("Control+y")
    assert until(lambda: pg.locator(".react-flow__edge").count() == 1)
    # the toolbar buttons do the same
    pg.get_by_test_id("undo").click()
    assert until(lambda: pg.locator(".react-flow__edge").count() == 0)
    pg.get_by_test_id("redo").click()
    assert until(lambda: pg.locator(".react-flow__edge").count() == 1)
    # copy / paste renames; delete removes; undo brings it back
    pg.locator('.react-flow__node[data-id="unicycle"]').click()
    pg.keyboard.press("Control+c")
    pg.keyboard.press("Control+v")
    pg.wait_for_selector('.react-flow__node[data-id="unicycle2"]')
    pg.keyboard.press("Delete")
    assert until(lambda: blocks_on_canvas(pg) == ["point_to_point", "unicycle"])
    pg.keyboard.press("Control+z")
    assert until(lambda: blocks_on_canvas(pg) == ["point_to_point", "unicycle", "unicycle2"])


def test_search_to_add_and_group(page):
    pg = page
    pg.keyboard.press("/")
    pg.keyboard.type("unicycle first")
    pg.keyboard.press("Enter")
    pg.wait_for_selector('.react-flow__node[data-id="unicycle"]')
    pg.keyboard.press("/")
    pg.keyboard.type("PointToPoint")
    pg.keyboard.press("Enter")
    pg.wait_for_selector('.react-flow__node[data-id="point_to_point"]')
    wire(pg, "unicycle.pose", "point_to_point.pose")
    wire(pg, "point_to_point.cmd", "unicycle.cmd")
    wait_edge(pg, "point_to_point.cmd->unicycle.cmd")
    pg.locator('.react-flow__node[data-id="point_to_point"]').click()
    pg.keyboard.press("Control+g")
    g = pg.locator(".react-flow__node-subsystem")
    g.wait_for()
    # the group's ports are the wires it cuts
    assert sorted(g.locator(".react-flow__handle").evaluate_all(
        "hs => hs.map(h => h.dataset.handleid)")) == ["point_to_point.cmd", "point_to_point.pose"]
    pg.keyboard.press("f")
    pg.wait_for_timeout(400)
    shot(pg, "group")
    g.dblclick()
    pg.wait_for_selector('.react-flow__node[data-id="point_to_point"]')
    pg.wait_for_timeout(400)
    shot(pg, "group-inside")
    assert pg.locator('.react-flow__node[data-id="unicycle"]').count() == 0
    assert pg.locator(".breadcrumb button").count() == 2
    pg.keyboard.press("Escape")
    pg.keyboard.press("Escape")
    pg.wait_for_selector(".react-flow__node-subsystem")


def test_formation_load_save_run_same_summary(page, editor_server, tmp_path_factory):
    pg = page
    # the built-in case study, laid out by elk (it carries no positions)
    pg.get_by_role("button", name="Open").click()
    pg.locator('[data-builtin="formation"]').click()
    pg.wait_for_selector('.react-flow__node[data-id="supervisor"]')
    wait_checked(pg)
    assert pg.get_by_test_id("check").inner_text().startswith("✓")
    # fitted at a readable zoom, it does not all fit at 1440 x 880: zoomed out, it is all there
    show_everything(pg, 6)
    assert blocks_on_canvas(pg) == ["collision", "drive", "fleet", "lf", "morph", "supervisor"]
    boxes = pg.eval_on_selector_all(
        ".react-flow__node-block",
        "ns => ns.map(n => { const r = n.getBoundingClientRect(); "
        "return [r.x, r.y, r.right, r.bottom]; })")
    for i, a in enumerate(boxes):
        for b in boxes[i + 1:]:
            assert not (a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]), (a, b)
    shot(pg, "formation")
    # a built-in has no file here: Ctrl+S asks for one, and the file keeps the built-in's comments
    pg.keyboard.press("Control+s")
    pg.get_by_label("File path").fill("from_builtin.yaml")
    pg.get_by_test_id("saveas-ok").click()
    pg.get_by_test_id("toast").filter(has_text="saved from_builtin.yaml").wait_for()
    assert "# the team is a leader and its followers" in (
        editor_server.root / "from_builtin.yaml").read_text()

    # the same file under the server's folder: open it, save it
    import avblocks.scenarios
    original = Path(avblocks.scenarios.__file__).parent / "formation.yaml"
    saved = editor_server.root / "formation.yaml"
    shutil.copy(original, saved)
    pg.get_by_role("button", name="Open").click()
    pg.locator('[data-file="formation.yaml"]').click()
    pg.wait_for_function("document.querySelector('[data-testid=file-title]').textContent.startsWith('formation.yaml')")
    pg.wait_for_selector('.react-flow__node[data-id="supervisor"]')
    pg.keyboard.press("Control+s")
    pg.get_by_test_id("toast").filter(has_text="saved formation.yaml").wait_for()
    text = saved.read_text()
    assert "# the team is a leader and its followers" in text  # comments kept
    assert "n: &n" in text and "*n" in text  # anchors kept
    assert "editor:" in text  # the layout under its own key

    # the saved file and the built-in run to the same summary
    out = tmp_path_factory.mktemp("runs")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    sums = []
    for target, name in [(str(saved), "saved"), ("formation", "builtin")]:
        subprocess.run([sys.executable, "-m", "avblocks", "run", target, "--quiet",
                        "--t-final", "4", "--out", str(out / name)],
                       check=True, env=env, cwd=out, timeout=600, stdout=subprocess.DEVNULL)
        s = json.loads((out / name / "summary.json").read_text())
        for k in ("realtime_factor", "wall_s", "files"):  # the clock and where it wrote
            s.pop(k)
        sums.append(s)
    assert sums[0] == sums[1]
    assert sums[0]["outcome"].startswith("wedge")

    # a file changed on disk since it was loaded: the page offers a choice
    saved.write_text(saved.read_text().replace("spacing: 1.5 ", "spacing: 1.6 "))
    click_empty(pg)
    pg.get_by_test_id("dparam-gain").fill("1.4")
    pg.keyboard.press("Control+s")
    # in plain words: what each choice does to the file and to the changes made here
    choices = pg.get_by_role("dialog", name="The file changed on disk").inner_text()
    assert "Save my diagram over it (its changes are lost)" in choices
    assert "Open the file as it is now (my changes are lost)" in choices
    assert "drop my changes" not in choices
    pg.get_by_test_id("overwrite").click()
    pg.wait_for_selector(".modal", state="detached")
    pg.get_by_test_id("toast").filter(has_text="saved formation.yaml").last.wait_for()
    text = saved.read_text()
    assert "gain: 1.4" in text and "spacing: 1.5 " in text


def test_help_overlay_and_python_export(page, editor_server):
    pg = page
    pg.keyboard.press("?")
    dialog = pg.get_by_role("dialog", name="Keyboard shortcuts")
    dialog.wait_for()
    assert "Ctrl+G" in dialog.inner_text()
    pg.keyboard.press("Escape")
    dialog.wait_for(state="detached")
    # the palette's + button adds a block where there is room in view
    for t in ("vehicles.Unicycle", "controllers.PointToPoint"):
        item = pg.locator(f'.palette-item[data-type="{t}"]')
        item.scroll_into_view_if_needed()
        item.hover()
        item.locator(".pi-add").click()
    pg.wait_for_selector('.react-flow__node[data-id="point_to_point"]')
    wire(pg, "unicycle.pose", "point_to_point.pose")
    wire(pg, "point_to_point.cmd", "unicycle.cmd")
    wait_checked(pg)
    # (saved first: a new diagram saved as exported.yaml is named after it)
    doc = current_document(pg, editor_server, "exported.yaml")
    assert doc["name"] == "exported"
    pg.get_by_label("Export").select_option("python")
    code = pg.locator("pre.code")
    code.wait_for()
    shown = code.inner_text()
    status, r = editor_server.post("export", {"document": doc, "format": "python"})
    assert status == 200
    assert shown.strip() == r["text"].strip()


TEAM_YAML = """\
# a team of {n}: a Unicycle fleet driven to random waypoints
name: team
parameters:
  agents: {n}
blocks:
  fleet:
    type: vehicles.Unicycle
    pose0: {{random_poses: {{n: $agents, area: [20, 20], seed: 3}}}}
  drive:
    type: controllers.PointToPoint
    n: $agents
    waypoints: {{random_waypoints: {{n: $agents, count: 2, area: [20, 20], seed: 4}}}}
wires:
  - [fleet.pose, drive.pose]
  - [drive.cmd, fleet.cmd]
simulation: {{t_final: 60, dt: 0.05}}
"""


def open_file(pg, editor_server, name, text):
    """Write a scenario file into the server's folder and open it in the page."""
    (editor_server.root / name).write_text(text)
    pg.get_by_role("button", name="Open").click()
    pg.locator(f'[data-file="{name}"]').click()
    pg.wait_for_function(f"document.querySelector('[data-testid=file-title]')"
                         f".textContent.startsWith('{name}')")
    wait_checked(pg)
    assert pg.get_by_test_id("check").inner_text().startswith("✓")


def _export_download(pg, fmt):
    with pg.expect_download() as dl:
        pg.get_by_label("Export").select_option(fmt)
    d = dl.value
    return d.suggested_filename, Path(d.path()).read_bytes()


def test_export_svg_and_png_from_the_page(page, editor_server):
    import base64
    import io
    import xml.etree.ElementTree as ET

    import numpy as np
    from PIL import Image
    pg = page
    open_file(pg, editor_server, "team.yaml", TEAM_YAML.format(n=7))

    # SVG: a well-formed SVG document naming every block of the diagram
    name, raw = _export_download(pg, "svg")
    assert name == "team.svg"
    root = ET.fromstring(raw)
    assert root.tag == "{http://www.w3.org/2000/svg}svg"
    texts = " ".join("".join(t.itertext()) for t in root.iter("{http://www.w3.org/2000/svg}text"))
    for block in ("fleet", "drive"):
        assert block in texts, (block, texts[:400])

    # PNG: decodes (Pillow) to the size of the server's own export of the same file, not blank
    name, raw = _export_download(pg, "png")
    assert name == "team.png"
    img = Image.open(io.BytesIO(raw))
    img.load()
    status, loaded = editor_server.post("load", {"path": "team.yaml"})
    status, ref = editor_server.post("export", {"document": loaded["document"], "format": "png"})
    assert status == 200, ref
    ref_img = Image.open(io.BytesIO(base64.b64decode(ref["data_url"].split(",", 1)[1])))
    assert img.size == ref_img.size and img.size[0] > 100 and img.size[1] > 100
    px = np.asarray(img.convert("RGB"), dtype=float)
    ink = (px.min(axis=2) < 200).mean()           # pixels that are not (near) white
    assert 0.005 < ink < 0.6, ink
    assert len(np.unique(px.reshape(-1, 3), axis=0)) > 8   # lines, text and fills, not one colour


def test_live_button_opens_the_drawn_diagram_in_the_live_view(page, editor_server):
    import re
    pg = page
    open_file(pg, editor_server, "team.yaml", TEAM_YAML.format(n=7))
    with pg.context.expect_page(timeout=60_000) as popup:
        pg.get_by_role("button", name="Live").click()
    live = popup.value
    try:
        port = int(re.match(r"http://127\.0\.0\.1:(\d+)/", live.url).group(1))
        assert port != editor_server.server.port       # the live view's own server
        # its status line: the diagram's agent count, and simulated time going on
        live.wait_for_function("/\\bt = [0-9.]+ s/.test(document.body.innerText)",
                               timeout=90_000)
        text = live.locator("body").inner_text()
        assert re.search(r"\b7 agents\b", text), text

        def t_page():
            m = re.search(r"\bt = ([0-9.]+) s", live.locator("body").inner_text())
            return float(m.group(1)) if m else None

        t0 = t_page()
        assert until(lambda: (t_page() or 0) > t0 + 0.2, timeout=30), (t0, t_page())
    finally:
        live.close()


def _red_pixels(png, box, pad=4):
    import io

    import numpy as np
    from PIL import Image
    img = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)
    x0, y0 = int(box["x"]) - pad, int(box["y"]) - pad
    x1, y1 = int(box["x"] + box["width"]) + pad, int(box["y"] + box["height"]) + pad
    sub = img[max(0, y0):y1, max(0, x0):x1]
    r, g, b = sub[..., 0], sub[..., 1], sub[..., 2]
    return int(((r > 180) & (r - g > 90) & (r - b > 90)).sum())


def test_a_block_with_an_error_stays_marked_zoomed_far_out(page, editor_server):
    """Zoomed out until ports are no longer drawn (a few hundred blocks in
    view), the block the check names is still red on the canvas and in the
    minimap; the block without an error is not."""
    pg = page
    text = TEAM_YAML.format(n=4).replace("  - [drive.cmd, fleet.cmd]\n", "")
    (editor_server.root / "half.yaml").write_text(text)
    pg.get_by_role("button", name="Open").click()
    pg.locator('[data-file="half.yaml"]').click()
    pg.wait_for_selector('.react-flow__node[data-id="fleet"]')
    wait_checked(pg)
    # the library's own verdict: fleet.cmd is not driven (and nothing about drive)
    status, loaded = editor_server.post("load", {"path": "half.yaml"})
    status, v = editor_server.post("validate", {"document": loaded["document"]})
    assert {e.get("block") for e in v["errors"]} == {"fleet"}, v["errors"]
    pane = pg.locator(".react-flow__pane").bounding_box()
    pg.mouse.move(pane["x"] + pane["width"] / 3, pane["y"] + pane["height"] / 3)
    for _ in range(40):
        if "tiny" in pg.locator(".canvas").get_attribute("class"):
            break
        pg.mouse.wheel(0, 240)
        pg.wait_for_timeout(60)
    assert "tiny" in pg.locator(".canvas").get_attribute("class")
    assert pg.locator(".react-flow__handle").first.is_hidden()      # ports not drawn
    pg.wait_for_timeout(300)
    png = pg.screenshot()
    fleet = pg.locator('.react-flow__node[data-id="fleet"]').bounding_box()
    drive = pg.locator('.react-flow__node[data-id="drive"]').bounding_box()
    assert fleet["width"] < 70                                        # really zoomed out
    assert _red_pixels(png, fleet) > 4 * fleet["width"], fleet
    assert _red_pixels(png, drive) == 0
    mini = pg.locator(".react-flow__minimap").bounding_box()
    assert _red_pixels(png, mini, pad=0) > 0


# ---------------------------------------------------------------------------- wires

# Geometry as the page draws it, in the canvas's own units: each node's rectangle (its
# transform and size) and each wire's path sampled every 2 units with the browser's own SVG
# geometry (getPointAtLength: the path as rendered, hops and rounded bends included).
GEOMETRY = """() => {
  const nodes = {};
  for (const n of document.querySelectorAll('.react-flow__node')) {
    const m = /translate\\(([-\\d.e]+)px,\\s*([-\\d.e]+)px\\)/.exec(n.style.transform);
    nodes[n.dataset.id] = {x: +m[1], y: +m[2], w: n.offsetWidth, h: n.offsetHeight};
  }
  const wires = [];
  for (const e of document.querySelectorAll('.react-flow__edge')) {
    const p = e.querySelector('path.react-flow__edge-path');
    const len = p.getTotalLength();
    const pts = [];
    for (let s = 0; s <= len; s += 2) { const q = p.getPointAtLength(s); pts.push([q.x, q.y]); }
    const q = p.getPointAtLength(len); pts.push([q.x, q.y]);
    wires.push({id: e.dataset.id, pts, d: p.getAttribute('d')});
  }
  return {nodes, wires};
}"""


def wires_under_blocks(geo):
    """``[(wire, block)]`` for each wire with a point inside a block it does not connect
    (and inside its own blocks away from its ends), from the rendered geometry."""
    bad = []
    for w in geo["wires"]:
        src, dst = (s.split(".")[0] for s in w["id"].split("->"))
        pts = w["pts"]
        for name, r in geo["nodes"].items():
            own = name in (src, dst)
            for k, (x, y) in enumerate(pts):
                if own and (k * 2 < 12 or (len(pts) - k) * 2 < 12):
                    continue                    # the port stubs start at the block's side
                if r["x"] + 1 < x < r["x"] + r["w"] - 1 and r["y"] + 1 < y < r["y"] + r["h"] - 1:
                    bad.append((w["id"], name))
                    break
    return bad


def ends_on_ports(geo):
    """Wires whose path does not start on its source block's right side and end on its
    target's left side (where the handles are)."""
    off = []
    for w in geo["wires"]:
        src, dst = (s.split(".")[0] for s in w["id"].split("->"))
        a, b = geo["nodes"].get(src), geo["nodes"].get(dst)
        (x0, y0), (x1, y1) = w["pts"][0], w["pts"][-1]
        if a is None or b is None:
            continue
        if not (abs(x0 - (a["x"] + a["w"] + 7)) < 1.5 and a["y"] < y0 < a["y"] + a["h"]
                and abs(x1 - (b["x"] - 7)) < 1.5 and b["y"] < y1 < b["y"] + b["h"]):
            off.append(w["id"])
    return off


# The page settles in steps after a document opens: its nodes are measured, the wires
# routed and drawn, then the view is fitted (a move scheduled a moment later). On a loaded
# machine (CI runs two workers on two cores) a test that reads the geometry, or zooms,
# before the last step saw no wires, or had its zoom undone by the late fit.
SETTLED = """n => {
  const v = document.querySelector('.react-flow__viewport')?.style.transform;
  const paths = [...document.querySelectorAll('.react-flow__edge path.react-flow__edge-path')];
  const key = v + '|' + paths.length + '|' + paths.map(p => p.getAttribute('d')).join(';');
  const now = performance.now();
  const s = window.__avSettled || (window.__avSettled = {key: null, since: now});
  if (s.key !== key) { s.key = key; s.since = now; return false; }
  return paths.length >= n && now - s.since > 400; }"""


def settled(pg, n_wires=0):
    """Wait until ``n_wires`` wires are drawn and the view and every wire's path have
    stayed as they are for 0.4 s (React Flow draws only the wires in view)."""
    pg.evaluate("() => { window.__avSettled = null; }")
    try:
        pg.wait_for_function(SETTLED, arg=n_wires, timeout=30_000)
    except Exception:
        seen = pg.evaluate("() => window.__avSettled")
        raise AssertionError(f"the page did not settle with {n_wires} wires: {seen}") from None


def open_builtin(pg, name, n_wires=0):
    pg.get_by_role("button", name="Open").click()
    pg.locator(f'[data-builtin="{name}"]').click()
    pg.wait_for_function(f"document.querySelector('[data-testid=file-title]')"
                         f".textContent.startsWith('{name} (built-in)')")
    pg.wait_for_selector(".react-flow__node-block")
    wait_checked(pg)
    settled(pg, n_wires)


def test_no_wire_under_a_block_in_any_builtin_scenario(page, editor_server):
    """Every built-in scenario the editor draws: no rendered wire passes under a block it
    does not connect, every wire starts and ends on its ports. Fitting the view keeps text
    readable: the zoom is at least the readable floor, and a block's name is >= 10 px."""
    pg = page
    status, files = editor_server.get("files")
    names = [b["name"] for b in files["builtins"] if b["editable"]]
    assert len(names) == 11, names
    for name in names:
        status, loaded = editor_server.post("load", {"builtin": name})
        open_builtin(pg, name)
        n = len(loaded["document"]["blocks"])
        zoom = pg.evaluate("parseFloat(/scale\\(([\\d.e-]+)\\)/.exec(document.querySelector("
                           "'.react-flow__viewport').style.transform)[1])")
        assert zoom >= 10 / 12 - 1e-6, (name, zoom)
        px = pg.evaluate("() => { const t = document.querySelector('.av-node-title'); "
                         "return t.getBoundingClientRect().height; }")
        assert px >= 10, (name, px)
        show_everything(pg, n)
        settled(pg, len(loaded["document"]["wires"]))
        geo = pg.evaluate(GEOMETRY)
        assert len(geo["wires"]) == len(loaded["document"]["wires"]), name
        assert wires_under_blocks(geo) == [], name
        assert ends_on_ports(geo) == [], name


def _random_document(seed, n_teams=4):
    """A diagram placed by hand (seeded): unicycles, controllers and gains on a jittered
    grid, never overlapping, wired at random output -> input."""
    import numpy as np
    rng = np.random.default_rng(seed)
    kinds = [("vehicles.Unicycle", {"pose0": {"random_poses": {"n": "$agents", "area": [9, 9],
                                                                "seed": 1}}},
              ["cmd"], ["pose"]),
             ("controllers.PointToPoint", {"waypoints": {"random_waypoints": {
                 "n": "$agents", "count": 2, "area": [9, 9], "seed": 2}}},
              ["pose"], ["cmd", "target", "arrived", "done"]),
             ("blocks.Gain", {"k": 2.0}, ["u"], ["y"])]
    blocks, layout, ins, outs = {}, {}, [], []
    cells = [(i, j) for i in range(4) for j in range(3)]
    rng.shuffle(cells)
    for k in range(3 * n_teams):
        typ, args, i_ports, o_ports = kinds[k % 3]
        name = f"b{k}"
        blocks[name] = {"type": typ, **args}
        ci, cj = cells[k]
        layout[name] = [int(ci * 430 + rng.integers(0, 90)), int(cj * 300 + rng.integers(0, 70))]
        ins += [f"{name}.{p}" for p in i_ports]
        outs += [f"{name}.{p}" for p in o_ports]
    rng.shuffle(ins)
    wires = [[str(rng.choice(outs)), dst] for dst in ins]
    return {"name": f"random{seed}", "parameters": {"agents": 3}, "blocks": blocks,
            "wires": wires, "simulation": {"t_final": 1, "dt": 0.1},
            "editor": {"layout": layout}}


def test_no_wire_under_a_block_on_random_hand_placements(page, editor_server):
    import yaml
    pg = page
    for seed in (1, 2, 3):
        doc = _random_document(seed)
        name = f"random{seed}.yaml"
        (editor_server.root / name).write_text(yaml.safe_dump(doc, sort_keys=False))
        pg.get_by_role("button", name="Open").click()
        pg.locator(f'[data-file="{name}"]').click()
        pg.wait_for_function(f"document.querySelector('[data-testid=file-title]')"
                             f".textContent.startsWith('{name}')")
        pg.wait_for_selector(".react-flow__node-block")
        wait_checked(pg)
        settled(pg)       # wires outside the view are not drawn until it is zoomed out
        show_everything(pg, len(doc["blocks"]))
        settled(pg, len(doc["wires"]))
        geo = pg.evaluate(GEOMETRY)
        assert len(geo["wires"]) == len(doc["wires"])
        assert wires_under_blocks(geo) == [], seed
        assert ends_on_ports(geo) == [], seed
        if seed == 1:
            shot(pg, "routing")


def _wire_visible(geo, wire_id):
    """The wire's rendered points outside every block (its own included, but its ends)."""
    w = next(x for x in geo["wires"] if x["id"] == wire_id)
    pts = w["pts"][6:-6]
    for name, r in geo["nodes"].items():
        for x, y in pts:
            if r["x"] <= x <= r["x"] + r["w"] and r["y"] <= y <= r["y"] + r["h"]:
                return False, name
    return True, None


def test_feedback_wires_are_drawn_round_the_blocks(page, editor_server):
    """waypoints' fleet.pose -> drive.pose and formation's fleet.pose -> lf.pose (the two
    the issue found hidden under blocks) run outside every block; the docs' pictures."""
    pg = page
    wires = {b: len(editor_server.post("load", {"builtin": b})[1]["document"]["wires"])
             for b in ("waypoints", "formation")}
    open_builtin(pg, "waypoints", wires["waypoints"])
    geo = pg.evaluate(GEOMETRY)
    assert _wire_visible(geo, "fleet.pose->drive.pose") == (True, None)
    # the feedback runs below the row of blocks it returns past
    w = next(x for x in geo["wires"] if x["id"] == "fleet.pose->drive.pose")
    bottom = max(r["y"] + r["h"] for r in geo["nodes"].values())
    assert max(y for _, y in w["pts"]) > bottom
    # fit view shows it where nothing floats over it: inside the canvas, clear of the
    # minimap and the zoom buttons
    pg.keyboard.press("f")
    pg.wait_for_timeout(400)
    pane = pg.locator(".react-flow__pane").bounding_box()
    covers = [pg.locator(".react-flow__minimap").bounding_box(),
              pg.locator(".react-flow__controls").bounding_box()]
    for n in pg.locator(".react-flow__node-block").all():
        r = n.bounding_box()
        assert pane["x"] <= r["x"] and r["x"] + r["width"] <= pane["x"] + pane["width"]
        assert pane["y"] <= r["y"] and r["y"] + r["height"] <= pane["y"] + pane["height"]
        assert not any(_boxes_overlap(r, c) for c in covers), (r, covers)
    shot(pg, "feedback-waypoints")
    open_builtin(pg, "formation", wires["formation"])
    show_everything(pg, 6)
    settled(pg, wires["formation"])
    geo = pg.evaluate(GEOMETRY)
    assert _wire_visible(geo, "fleet.pose->lf.pose") == (True, None)
    # it does not run into the supervisor's u port (the misreading)
    w = next(x for x in geo["wires"] if x["id"] == "fleet.pose->lf.pose")
    sup = geo["nodes"]["supervisor"]
    assert all(not (abs(x - (sup["x"] - 7)) < 3 and sup["y"] < y < sup["y"] + sup["h"])
               for x, y in w["pts"][5:-5])
    shot(pg, "feedback-formation")


# ---------------------------------------------------------------------------- stop

#: The wall time a Stop must end a stepping run in, stated in docs/editor.md (0.5 s).
#: Asserted with room for a loaded shared machine (the figure measured is printed).
STOP_STATED_S = 0.5
STOP_ASSERTED_S = 5.0

LONG_YAML = TEAM_YAML.format(n=7).replace(
    "simulation: {t_final: 60, dt: 0.05}",
    "simulation: {t_final: 60, dt: 0.05, log_every: 1000, log: [fleet.pose, drive.cmd]}")


def _run_id(pg):
    pg.wait_for_function("document.querySelector('[data-testid=run-state]')?.dataset.run",
                         timeout=60_000)
    return pg.get_by_test_id("run-state").get_attribute("data-run")


def _stepping(editor_server, rid, timeout=180):
    """Wait until the run has simulated some time (JAX: compiled and stepping)."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        status, s = editor_server.get(f"run/{rid}")
        if s["status"] != "running" or s["t"] > 0:
            return s
        time.sleep(0.05)
    raise AssertionError("the run did not start stepping")


@pytest.mark.parametrize("backend", ["numpy", "jax"])
def test_stop_ends_a_long_run_at_once_and_keeps_what_was_computed(page, editor_server, backend):
    if backend == "jax":
        import importlib.util
        if importlib.util.find_spec("jax") is None:
            if os.environ.get("CI"):
                pytest.fail("CI installs the jax extra")
            pytest.skip("needs jax")
    pg = page
    open_file(pg, editor_server, "long.yaml", LONG_YAML)
    pg.get_by_label("Backend").select_option(backend)
    pg.get_by_label("t_final").fill("1e6")              # 20 million steps
    wait_checked(pg)
    pg.get_by_test_id("run").click()
    rid = _run_id(pg)
    s = _stepping(editor_server, rid)
    assert s["status"] == "running"
    pg.wait_for_timeout(300)
    t0 = time.monotonic()
    pg.get_by_test_id("stop").click()
    pg.locator(".run-state.cancelled").wait_for(timeout=60_000)
    took = time.monotonic() - t0
    print(f"\n{backend}: stopped {took:.3f} s after Stop (stated: {STOP_STATED_S} s)")
    assert took < STOP_ASSERTED_S
    status, s = editor_server.get(f"run/{rid}")
    assert s["status"] == "cancelled" and 0 < s["t"] < 1e6
    assert "stopped at t =" in pg.get_by_test_id("run-state").inner_text().lower()
    # what was computed until the stop: plotted from the page, the server's samples
    status, sig = editor_server.get(f"run/{rid}/signal?name=fleet.pose")
    assert status == 200 and len(sig["t"]) >= 1
    pg.locator('[data-wire="fleet.pose->drive.pose"]').click()
    pg.get_by_test_id("signal-plot").wait_for(timeout=30_000)
    assert pg.locator('[data-testid="signal-plot"] path').count() == 3


def test_two_stopped_runs_do_not_block_a_new_one(page, editor_server):
    pg = page
    open_file(pg, editor_server, "long.yaml", LONG_YAML)
    status, loaded = editor_server.post("load", {"path": "long.yaml"})
    doc = loaded["document"]
    ids = []
    for _ in range(2):
        status, r = editor_server.post("run", {"document": doc, "t_final": 1e6})
        assert status == 200, r
        ids.append(r["run"])
    for rid in ids:
        _stepping(editor_server, rid)
    status, r = editor_server.post("run", {"document": doc, "t_final": 1e6})
    assert status == 409 and r["error"]["kind"] == "Busy"
    for rid in ids:
        editor_server.post(f"run/{rid}/cancel")
    t0 = time.monotonic()
    assert until(lambda: all(editor_server.get(f"run/{rid}")[1]["status"] == "cancelled"
                             for rid in ids), timeout=STOP_ASSERTED_S)
    print(f"\nboth stopped within {time.monotonic() - t0:.3f} s")
    # a new run from the page starts and finishes
    pg.get_by_label("t_final").fill("1")
    wait_checked(pg)
    pg.get_by_test_id("run").click()
    pg.locator(".run-state.done").wait_for(timeout=120_000)


# ---------------------------------------------------------------------------- fields

def _library_error(fn):
    """The library's own message for a value (the block constructed here, not by the editor)."""
    from avblocks.core.errors import AvError
    try:
        fn()
    except AvError as e:
        return str(e)
    raise AssertionError("the library accepted it")


def _field_error(pg, testid):
    loc = pg.get_by_test_id(f"{testid}-error")
    loc.first.wait_for(timeout=30_000)
    return [t.strip() for t in loc.all_inner_texts()]


def _select_block(pg, name):
    pg.locator(f'.react-flow__node[data-id="{name}"] .av-node-head').click()
    pg.get_by_role("button", name="Properties").click()
    pg.get_by_test_id("block-panel").wait_for()


def test_fields_show_the_library_words_on_the_field_that_caused_them(page, editor_server):
    """Each case of issue 44: the message the page shows on the field is the library's own
    (the block constructed directly here with the same value), and nothing else is blamed."""
    import math

    import numpy as np

    import avblocks as av
    pg = page
    open_file(pg, editor_server, "team.yaml", TEAM_YAML.format(n=7))
    wps = np.zeros((7, 2, 2))

    def drive(**kw):
        return av.controllers.PointToPoint(wps, n=7, **kw)

    _select_block(pg, "drive")
    cases = [("gain", "[1, 2, 3, 4, 5]", lambda: drive(gain=[1, 2, 3, 4, 5])),
             ("gain", ".nan", lambda: drive(gain=math.nan)),
             ("gain", "1e999", lambda: drive(gain=math.inf)),
             ("n", "-3", lambda: av.controllers.PointToPoint(wps, n=-3))]
    for param, text, truth in cases:
        pg.get_by_test_id(f"param-{param}").fill(text)
        wait_checked(pg)
        shown = _field_error(pg, f"param-{param}")
        assert shown == [_library_error(truth)], (param, text, shown)
        # the wired input it drives is not blamed ("input is not connected")
        assert pg.locator('.react-flow__node[data-id="fleet"] .react-flow__handle.bad').count() == 0
        problems = pg.get_by_test_id("tab-problems").inner_text()
        assert problems.strip().endswith("1"), (text, problems)
        pg.get_by_test_id(f"param-{param}").fill("")
        wait_checked(pg)
    assert pg.get_by_test_id("check").inner_text().startswith("✓")
    # a gain per agent (7 of them) builds, as the library takes it
    pg.get_by_test_id("param-gain").fill("[1, 1, 1, 1, 1, 1, 1]")
    wait_checked(pg)
    assert pg.get_by_test_id("check").inner_text().startswith("✓")
    assert pg.get_by_test_id("param-gain-error").count() == 0
    pg.get_by_test_id("param-gain").fill("")

    # agents = 0: a message in words on the agents field itself; no NumPy text anywhere
    click_empty(pg)
    pg.get_by_test_id("dparam-agents").fill("0")
    wait_checked(pg)
    shown = _field_error(pg, "dparam-agents")
    from avblocks.core.params import integer
    own = _library_error(lambda: integer(0, None, "agents", lo=1))
    assert shown[0] == own.replace("in parameter 'agents': ", "'agents' is an agent count: ")
    pg.get_by_test_id("tab-problems").click()
    text = pg.get_by_test_id("problems").inner_text()
    assert "zero-size" not in text and "ValueError" not in text and "reduction" not in text
    assert "is empty" in text                                     # drive's waypoints, in words
    pg.get_by_role("button", name="Properties").click()
    pg.get_by_test_id("dparam-agents").fill("abc")
    wait_checked(pg)
    assert _field_error(pg, "dparam-agents")[0] == _library_error(
        lambda: integer("abc", None, "agents", lo=1)).replace(
        "in parameter 'agents': ", "'agents' is an agent count: ")
    pg.get_by_test_id("dparam-agents").fill("7")
    wait_checked(pg)
    assert pg.get_by_test_id("check").inner_text().startswith("✓")

    # t_final typed as abc in the toolbar: an error on that field, and Run refuses with it
    pg.get_by_label("t_final").fill("abc")
    from avblocks.core.runguard import finite_number
    words = _library_error(lambda: finite_number("abc", "t_final"))
    err = pg.get_by_test_id("t_final-error")
    err.wait_for(timeout=30_000)
    assert err.inner_text().strip() == words.replace("in parameter 't_final': ", "")
    pg.get_by_test_id("run").click()
    refused = pg.get_by_test_id("run-refused")
    refused.wait_for()
    assert words.replace("in parameter 't_final': ", "") in refused.inner_text()
    assert pg.get_by_test_id("stop").count() == 0                  # nothing started

    # text the page cannot read is not dropped: a problem until fixed
    pg.get_by_label("t_final").fill("")
    _select_block(pg, "drive")
    pg.get_by_test_id("param-gain").fill("[1, 2")
    assert "not applied" in _field_error(pg, "param-gain")[0]
    assert not pg.get_by_test_id("check").inner_text().startswith("✓")
    pg.get_by_test_id("param-gain").fill("2")
    wait_checked(pg)
    assert pg.get_by_test_id("check").inner_text().startswith("✓")


# ---------------------------------------------------------------------------- not stuck

def _search(pg, q):
    pg.keyboard.press("/")
    pg.get_by_label("Search blocks").fill(q)
    res = pg.get_by_test_id("search-results")
    res.wait_for()
    return res.locator(".palette-item").evaluate_all("ns => ns.map(n => n.dataset.type)")


def test_search_by_words_and_synonyms_ranked(page, editor_server):
    """Name matches first, then words of the summary, then synonyms: what a newcomer types
    finds the block (the palette's own summaries are the truth for the middle tier)."""
    pg = page
    found = _search(pg, "goal")
    assert "controllers.PointToPoint" in found[:3], found
    # "goal" is a word of NavigationLaw's summary: it ranks above a match by synonym
    status, pal = editor_server.get("palette")
    summaries = {b["type"]: b["summary"].lower() for f in pal["families"] for b in f["blocks"]}
    with_word = [t for t in found if " goal" in " " + summaries[t]]
    assert with_word and found.index(with_word[0]) < found.index("controllers.PointToPoint")
    assert _search(pg, "go to")[0] == "controllers.PointToPoint"
    assert _search(pg, "waypoint")[0] == "controllers.PointToPoint"
    assert _search(pg, "leader")[0] == "controllers.LeaderFollower"
    assert _search(pg, "follow")[0] == "controllers.LeaderFollower"
    assert "controllers.Flocking" in _search(pg, "swarm")[:4]
    assert _search(pg, "avoid")[0] == "controllers.CollisionAvoidance"
    assert _search(pg, "point")[0] == "controllers.PointToPoint"       # the name first
    # Enter adds the first
    pg.get_by_label("Search blocks").fill("go to")
    pg.keyboard.press("Enter")
    pg.wait_for_selector('.react-flow__node[data-id="point_to_point"]')


def test_ctrl_s_asks_before_a_draft_replaces_a_file_that_runs(page, editor_server):
    pg = page
    open_file(pg, editor_server, "team.yaml", TEAM_YAML.format(n=7))
    path = editor_server.root / "team.yaml"
    before = path.read_text()
    _select_block(pg, "drive")
    pg.get_by_test_id("param-gain").fill("-1")
    wait_checked(pg)
    pg.keyboard.press("Control+s")
    dialog = pg.get_by_role("dialog", name="Save it with problems?")
    dialog.wait_for()
    assert "avblocks run will refuse" in " ".join(dialog.inner_text().split())
    assert path.read_text() == before                      # nothing written yet
    pg.get_by_test_id("guard-show").click()
    pg.get_by_test_id("problems").wait_for()
    assert path.read_text() == before
    pg.keyboard.press("Control+s")
    pg.get_by_test_id("guard-draft").click()
    pg.get_by_test_id("toast").filter(has_text="as a draft").wait_for()
    assert "gain: -1" in path.read_text()
    # the saved draft is what avblocks run refuses; fixed, it saves without a question
    _select_block(pg, "drive")
    pg.get_by_test_id("param-gain").fill("2")
    wait_checked(pg)
    pg.keyboard.press("Control+s")
    assert until(lambda: "gain: 2" in path.read_text())
    assert pg.get_by_role("dialog").count() == 0


def test_a_refused_run_lists_its_problems_each_a_link(page, editor_server):
    pg = page
    open_file(pg, editor_server, "team.yaml", TEAM_YAML.format(n=7))
    _select_block(pg, "drive")
    pg.get_by_test_id("param-radius").fill("-1")
    wait_checked(pg)
    click_empty(pg)
    pg.get_by_test_id("run").click()
    refused = pg.get_by_test_id("run-refused")
    refused.wait_for()
    items = refused.get_by_test_id("problem")
    assert items.count() == 1
    assert "drive.radius" in items.first.inner_text()
    items.first.click()
    assert until(lambda: pg.locator('.react-flow__node[data-id="drive"].selected').count() == 1)
    assert "out of range" in _field_error(pg, "param-radius")[0]


def test_new_diagram_defaults_save_as_names_it_and_palette_text(page, editor_server):
    pg = page
    # the page's new diagram is GET new's, and the API's page says the same
    pg.get_by_role("button", name="New").click()
    click_empty(pg)
    status, new = editor_server.get("new")
    sim = new["document"]["simulation"]
    assert (sim["t_final"], sim["dt"]) == (30, 0.02)
    assert pg.get_by_test_id("sim-t_final").input_value() == "30"
    assert pg.get_by_test_id("sim-dt").input_value() == "0.02"
    api_doc = (Path(__file__).resolve().parents[2] / "docs" / "editor-api.md").read_text()
    assert "`simulation: {t_final: 30, dt: 0.02}`" in api_doc
    # palette text is rendered: code as code, no reStructuredText left
    text = pg.get_by_test_id("palette-list").inner_text()
    assert "``" not in text and ":class:" not in text and ":func:" not in text
    gain = pg.locator('.palette-item[data-type="blocks.Gain"]')
    gain.scroll_into_view_if_needed()
    gain.hover()
    card = pg.get_by_test_id("block-card")
    assert card.locator("code").first.inner_text() == "y = k * u"
    # Save as names the diagram after the file (its runs' outputs go to avblocks-out/<name>)
    pg.keyboard.press("/")
    pg.keyboard.type("unicycle first")
    pg.keyboard.press("Enter")
    pg.wait_for_selector('.react-flow__node[data-id="unicycle"]')
    pg.keyboard.press("Escape")
    pg.keyboard.press("Control+Shift+S")
    pg.get_by_label("File path").fill("my_team.yaml")
    pg.get_by_test_id("saveas-ok").click()
    pg.get_by_test_id("toast").filter(has_text="my_team.yaml").wait_for()
    status, loaded = editor_server.post("load", {"path": "my_team.yaml"})
    assert loaded["document"]["name"] == "my_team"
    assert pg.locator(".breadcrumb").inner_text().strip() == "my_team"


# ---------------------------------------------------------------------------- beyond

def _boxes_overlap(a, b):
    return a["x"] < b["x"] + b["width"] and b["x"] < a["x"] + a["width"] and \
        a["y"] < b["y"] + b["height"] and b["y"] < a["y"] + a["height"]


def test_several_signals_in_one_plot_with_a_time_cursor_on_the_canvas(page, editor_server):
    """Two wires plotted in one panel on one time axis; hovering a time shows each wire's
    value on the canvas, the server's logged sample at that time (read here through the API).
    The time axis's label does not overlap its last tick."""
    import re
    pg = page
    open_file(pg, editor_server, "team.yaml", TEAM_YAML.format(n=7).replace(
        "simulation: {t_final: 60, dt: 0.05}",
        "simulation: {t_final: 4, dt: 0.05, log: [fleet.pose, drive.cmd]}"))
    pg.get_by_test_id("run").click()
    pg.locator(".run-state.done").wait_for(timeout=120_000)
    rid = _run_id(pg)
    pg.locator('[data-wire="fleet.pose->drive.pose"]').click()
    pg.locator('[data-signal="fleet.pose"]').wait_for(timeout=30_000)
    pg.locator('[data-wire="drive.cmd->fleet.cmd"]').click(modifiers=["Shift"])
    pg.locator('[data-signal="drive.cmd"]').wait_for(timeout=30_000)
    assert pg.get_by_test_id("signal-plot").count() == 2
    # the axis label and the ticks of the time axis
    label = pg.locator(".axis-label").bounding_box()
    for t in pg.locator(".x-tick").all():
        assert not _boxes_overlap(label, t.bounding_box())
    # hover 60 % along the first plot's time axis
    box = pg.locator('[data-signal="fleet.pose"]').bounding_box()
    pg.mouse.move(box["x"] + 52 + 0.6 * (box["width"] - 64), box["y"] + box["height"] / 2)
    pg.get_by_test_id("plot-cursor").first.wait_for()
    values = {v.get_attribute("data-wire-value"): v.inner_text()
              for v in pg.locator(".av-wire-value").all()}
    assert set(values) == {"fleet.pose", "drive.cmd"}, values
    readout = pg.locator(".readout").first.inner_text()
    t_cursor = float(re.search(r"t=([-\d.e]+)", readout).group(1))
    for name in ("fleet.pose", "drive.cmd"):
        status, sig = editor_server.get(f"run/{rid}/signal?name={name}")
        i = min(range(len(sig["t"])), key=lambda k: abs(sig["t"][k] - t_cursor))
        agent, nums = re.match(r"\[(\d+)\] \((.*)\)", values[name]).groups()
        shown = [float(x) for x in nums.split(", ")]
        assert shown == pytest.approx(sig["values"][i][int(agent)], rel=1e-3, abs=1e-3), name
    shot(pg, "plot")


def test_sliders_rerun_on_the_compiled_engine_with_the_value(page, editor_server):
    """Tune: a slider sets params: {drive.v_max: v} and the diagram runs again on JAX; its
    signals are those of the NumPy engine run here with params={'drive.v_max': v}."""
    import importlib.util
    if importlib.util.find_spec("jax") is None:
        if os.environ.get("CI"):
            pytest.fail("CI installs the jax extra")
        pytest.skip("needs jax")
    import numpy as np

    import avblocks as av
    from avblocks.scenarios.loader import Scenario
    pg = page
    text = TEAM_YAML.format(n=5).replace("simulation: {t_final: 60, dt: 0.05}",
                                         "simulation: {t_final: 3, dt: 0.05}")
    open_file(pg, editor_server, "team.yaml", text)
    pg.get_by_test_id("tab-tune").click()
    knob = pg.get_by_test_id("knob-drive.v_max")
    knob.wait_for()
    notes = []
    for v in ("1.5", "1.8"):
        knob.evaluate("""(el, v) => { const set = Object.getOwnPropertyDescriptor(
            HTMLInputElement.prototype, 'value').set; set.call(el, v);
            el.dispatchEvent(new Event('input', {bubbles: true})); }""", v)
        pg.wait_for_function("document.querySelector('[data-testid=tune-note]')"
                             f"?.textContent.startsWith('ran again') && document.querySelector("
                             f"'[data-knob=\"drive.v_max\"] .knob-value').textContent === '{v}'",
                             timeout=180_000)
        notes.append(pg.get_by_test_id("tune-note").inner_text())
    print("\n" + "\n".join(notes))
    shot(pg, "tune")
    pg.get_by_test_id("tab-run").click()
    rid = _run_id(pg)
    status, st = editor_server.get(f"run/{rid}")
    assert st["status"] == "done" and st["figures"] == []       # a quick run: no figures
    status, sig = editor_server.get(f"run/{rid}/signal?name=fleet.pose")
    doc = current_document(pg, editor_server, "tuned.yaml")
    assert doc["params"] == {"drive.v_max": 1.8}
    d, sim = Scenario({k: v for k, v in doc.items() if k != "editor"}, "tuned.yaml").build(
        editor_server.root / "out")
    assert sim.pop("params") is not None
    ref = av.simulate(d, progress=False, params={"drive.v_max": 1.8}, **sim)
    np.testing.assert_allclose(np.asarray(sig["values"])[-1], ref["fleet.pose"][-1], atol=1e-6)
    # and the value matters: the block's own speed cap gives another run
    base = av.simulate(d, progress=False, **sim)
    assert not np.allclose(base["fleet.pose"][-1], ref["fleet.pose"][-1], atol=1e-6)


def test_hover_lights_a_wire_and_a_port_its_whole_signal_junctions_and_hops(page, editor_server):
    pg = page
    open_builtin(pg, "formation")
    show_everything(pg, 6)
    status, loaded = editor_server.post("load", {"builtin": "formation"})
    from_fleet = [w for w in loaded["document"]["wires"] if w[0] == "fleet.pose"]
    assert len(from_fleet) >= 3
    # a port: every wire of its signal lit
    pg.locator('.react-flow__node[data-id="fleet"] .react-flow__handle.source'
               '[data-handleid="pose"]').hover(force=True)
    assert until(lambda: pg.locator("path.av-wire.lit").count() == len(from_fleet))
    lit = pg.locator(".react-flow__edge:has(path.av-wire.lit)").evaluate_all(
        "es => es.map(e => e.dataset.id)")
    assert sorted(lit) == sorted(f"{a}->{b}" for a, b in from_fleet)
    pg.mouse.move(5, 5)
    assert until(lambda: pg.locator("path.av-wire.lit").count() == 0)
    # a wire: its name shown where it runs
    geo = pg.evaluate(GEOMETRY)
    w = next(x for x in geo["wires"] if x["id"] == "lf.cmd->fleet.cmd")
    # the mouse onto the middle of its path, as drawn
    x, y = pg.evaluate("""id => { const p = document.querySelector(
        `.react-flow__edge[data-id="${id}"] path.react-flow__edge-path`);
        const q = p.getPointAtLength(p.getTotalLength() / 2);
        const s = new DOMPoint(q.x, q.y).matrixTransform(p.getScreenCTM());
        return [s.x, s.y]; }""", "lf.cmd->fleet.cmd")
    pg.mouse.move(x, y)
    name = pg.locator(".av-wire-name")
    name.wait_for()
    assert name.inner_text().startswith("lf.cmd → fleet.cmd")
    # junction dots: each where wires of one signal part, on two or more of them (within
    # the 2 px a rounded bend cuts off its corner)
    dots = pg.locator("circle.av-junction").evaluate_all(
        "cs => cs.map(c => [+c.getAttribute('cx'), +c.getAttribute('cy')])")
    assert dots
    for cx, cy in dots:
        on = [x["id"] for x in geo["wires"]
              if any(abs(px - cx) < 3 and abs(py - cy) < 3 for px, py in x["pts"])]
        assert len(on) >= 2 and len({i.split("->")[0] for i in on}) == 1, (cx, cy, on)
    del w
    # hops (honeybee's wires cross): each arc is over a vertical run of another signal
    open_builtin(pg, "honeybee")
    status, hb = editor_server.post("load", {"builtin": "honeybee"})
    show_everything(pg, len(hb["document"]["blocks"]))
    geo = pg.evaluate(GEOMETRY)
    import re
    hops = []
    for x in geo["wires"]:
        for m in re.finditer(r"L([-\d.]+),([-\d.]+)A4,4 0 0 [01] ([-\d.]+),([-\d.]+)", x["d"]):
            hops.append((x["id"], (float(m.group(1)) + float(m.group(3))) / 2, float(m.group(2))))
    assert hops
    for wid, hx, hy in hops:
        src = wid.split("->")[0]
        crossing = [x["id"] for x in geo["wires"] if x["id"].split("->")[0] != src
                    and any(abs(px - hx) < 1.5 and py < hy - 3 for px, py in x["pts"])
                    and any(abs(px - hx) < 1.5 and py > hy + 3 for px, py in x["pts"])]
        assert crossing, (wid, hx, hy)
