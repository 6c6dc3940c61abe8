"""Screenshots of the live view for docs/live.md (headless Chromium).

Run: ``python docs/live_screenshots.py`` (writes docs/img/live-*.png).
Each run is paused before the shot (a software-GL browser on a busy
machine draws moving scenes washed out; a paused one settles).
"""

from __future__ import annotations

import importlib.util
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests", "viz"))

from test_live import _browser  # noqa: E402

from avblocks.scenarios import formation  # noqa: E402
from avblocks.viz.live import LiveView  # noqa: E402


def shot(drv, view, path, run_for):
    """Open the page, pause at simulated time ``run_for``, save a shot."""
    view.start()
    try:
        drv.get(view.url)
        t_end = time.monotonic() + 60.0      # until simulated time run_for
        while view.sim.t < run_for and time.monotonic() < t_end:
            time.sleep(0.05)
        view.pause()
        time.sleep(4.0)
        drv.execute_script("document.querySelectorAll('.mantine-Notification-root')"
                           ".forEach(e => e.remove());")
        time.sleep(0.5)
        drv.save_screenshot(path)
        print("wrote", path)
    finally:
        view.close()


def main():
    out = os.path.join(HERE, "images")
    os.makedirs(out, exist_ok=True)
    drv = _browser()
    try:
        d, sim = formation.make_diagram()
        sim.pop("t_final")
        shot(drv, LiveView(d, t_final=100.0, realtime=8.0, verbose=False, **sim),
             os.path.join(out, "live-formation.png"), 18.0)
        spec = importlib.util.spec_from_file_location(
            "quads", os.path.join(HERE, "..", "examples", "07_live_quadrotors.py"))
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        d, sim = mod.make_diagram()
        sim.pop("t_final")
        shot(drv, LiveView(d, t_final=60.0, realtime=2.0, verbose=False, **sim),
             os.path.join(out, "live-quadrotors.png"), 20.0)
    finally:
        drv.quit()


if __name__ == "__main__":
    main()
