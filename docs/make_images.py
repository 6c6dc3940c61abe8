"""Regenerate every picture of the README and the docs (``docs/images/``).

    python docs/make_images.py                 # the quick ones (scenarios, snippets, drawings)
    python docs/make_images.py --all           # also benchmarks, browser shots, MuJoCo
    python docs/make_images.py nest diagram    # some, by name (without .png)
    python docs/make_images.py --list          # every picture and what makes it
    python docs/make_images.py --check         # pages name only pictures made here

:data:`PRODUCERS` names what makes each picture: a case study's own figure
(exactly what ``avblocks run NAME`` writes, copied to
``scenario_NAME.png`` by ``docs/regenerate.py``, which also rewrites the
numbers the pages quote from the same run), a docs page's own snippets, a drawing function in
this file, or a script of the repository (benchmarks, examples, browser
screenshots). ``tests/test_docs_site.py`` fails when a page names a picture
that is not made here, or a picture here is named by no page.
"""

from __future__ import annotations

import os
import re
import shutil
import sys
import tempfile
from pathlib import Path

from avblocks.cli import main
from avblocks.scenarios import builtin_scenarios

ROOT = Path(__file__).resolve().parents[1]

DOCS = Path(__file__).resolve().parent
IMAGES = DOCS / "images"

_FENCE = re.compile(r"^(?P<indent>[ ]*)```python[ ]*\n(?P<code>.*?)^(?P=indent)```[ ]*$",
                    re.S | re.M)
_SKIP = re.compile(r"<!--\s*no-test\b[^>]*-->\s*$")


def python_blocks(path, partial=False):
    """``[(line, code)]`` of the fenced ```python blocks of a Markdown file,
    in order, without those right after a ``<!-- no-test: why -->`` line
    (or only those, the partial ones, with ``partial=True``)."""
    text = Path(path).read_text()
    out = []
    for m in _FENCE.finditer(text):
        before = text[:m.start()].rstrip("\n").rsplit("\n", 1)[-1]
        if bool(_SKIP.search(before)) != partial:
            continue
        ind = len(m.group("indent"))
        code = "\n".join(ln[ind:] for ln in m.group("code").splitlines())
        out.append((text.count("\n", 0, m.start()) + 1, code))
    return out


def run_blocks(path, cwd):
    """Run a Markdown file's Python blocks in order, in one namespace, in
    the folder ``cwd``; returns the namespace."""
    ns = {"__name__": "__snippets__"}
    old = os.getcwd()
    os.chdir(cwd)
    try:
        for line, code in python_blocks(path):
            exec(compile(code, f"{path}:{line}", "exec"), ns)
    finally:
        os.chdir(old)
    return ns


def make(name: str) -> Path:
    """A case study's figure. For those of ``docs/regenerate.py`` this is
    that script (the same run also rewrites the numbers the pages quote)."""
    regen = _regenerate()
    if name in regen.CASES:
        problems = regen.regenerate([name])
        if problems:
            raise SystemExit("\n".join(problems))
        return IMAGES / f"scenario_{name}.png"
    with tempfile.TemporaryDirectory() as tmp:
        rc = main(["run", name, "--out", tmp, "--quiet"])
        if rc != 0:
            raise SystemExit(f"avblocks run {name} failed ({rc})")
        src = Path(tmp) / f"{name}.png"
        if not src.is_file():
            raise SystemExit(f"scenario {name} wrote no {name}.png")
        dst = IMAGES / f"scenario_{name}.png"
        shutil.copyfile(src, dst)
    print(f"wrote {dst}")
    return dst


def _regenerate():
    import importlib.util
    spec = importlib.util.spec_from_file_location("regenerate", DOCS / "regenerate.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _page(page, *names):
    """Run a docs page's snippets in docs/images (they save ``names``)."""
    def make_page():
        import matplotlib
        matplotlib.use("Agg")
        run_blocks(DOCS / page, IMAGES)
        for extra in ("run.gif", "run.mp4", "lab7_policy.npz"):
            (IMAGES / extra).unlink(missing_ok=True)
    return make_page


def _script(cmd, made=None, frame=None):
    """Run ``cmd`` (a list; ``{images}`` and ``{tmp}`` are filled in) from the
    repository root; copy ``made`` (a file it writes in ``{tmp}``) to the
    picture, or a frame (a fraction of the length) of the movie ``made``."""
    def run_script(name):
        import subprocess
        with tempfile.TemporaryDirectory() as tmp:
            args = [a.format(images=IMAGES, tmp=tmp) for a in cmd]
            subprocess.run(args, cwd=tmp if made else ROOT, check=True,
                           env={**os.environ, "MPLBACKEND": "Agg"})
            if made is not None:
                src = Path(tmp) / made
                if frame is None:
                    shutil.copyfile(src, IMAGES / f"{name}.png")
                else:
                    from PIL import Image

                    from avblocks.viz import read_video
                    frames = read_video(src)
                    Image.fromarray(frames[int(frame * (len(frames) - 1))]).save(
                        IMAGES / f"{name}.png")
    return run_script


def draw_diagram_picture(name):
    """The wiring of a small rendezvous diagram (vehicles, sensing at its
    own rate, a controller), drawn by :func:`avblocks.viz.draw_diagram`."""
    import numpy as np

    import avblocks as av
    n = 12
    d = av.Diagram()
    agents = d.add(av.vehicles.SingleIntegrator(position0=np.zeros((n, 2))), name="agents")
    sense = d.add(av.environment.Neighbors(n, k=4, radius=12.0, input="position",
                                           period=0.1), name="sense")
    law = d.add(av.controllers.Consensus(n, gain=0.5), name="law")
    scope = d.add(av.viz.Scope(inputs=("position",)), name="scope")
    d.connect(agents.position, sense.position)
    d.connect(agents.position, law.position)
    d.connect(sense.neighbors, law.neighbors)
    d.connect(law.velocity, agents.velocity)
    d.connect(agents.position, scope.position)
    av.viz.draw_diagram(d, IMAGES / f"{name}.png", engine="matplotlib")


def draw_animation_frame(name):
    """One frame of a 2D animation: every vehicle family's drawing, trails,
    obstacles and a background."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    import avblocks as av
    families = ["unicycle", "car", "quadrotor", "blimp", "robot", "arrow"]
    n = 6 * len(families)
    d = av.Diagram()
    p0 = av.utility.random_poses(n, area=(24, 24), seed=3) - np.array([12.0, 12.0, 0.0])
    fleet = d.add(av.vehicles.Unicycle(pose0=p0), name="fleet")
    rng = np.random.default_rng(4)
    cmd = np.column_stack([rng.uniform(0.8, 1.6, n), rng.uniform(-0.4, 0.4, n)])
    go = d.add(av.blocks.Constant(cmd), name="go")
    d.connect(go.y, fleet.cmd)
    res = av.simulate(d, 6.0, dt=0.05, log=[fleet.pose])
    world = av.environment.World(obstacles=[av.environment.rectangle(-3, -3, 0, -1),
                                            av.environment.Circle((5, 5), 1.5),
                                            [(6, -6), (9, -6), (7.5, -3)]])
    groups = [av.viz.Group(agents=slice(k, None, len(families)), drawing=f, size=1.2, label=f)
              for k, f in enumerate(families)]
    fig = av.viz.plot_frame(res, t=6.0, trail=3.0, world=world, groups=groups,
                            title="avblocks Animation2D")
    fig.savefig(IMAGES / f"{name}.png", dpi=100)
    plt.close(fig)


def draw_uav3d(name):
    """Quadrotors in 3D (:func:`avblocks.viz.animate3d`), last frame."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    import avblocks as av
    n = 5
    a = 2 * np.pi * np.arange(n) / n
    start = np.column_stack([3 * np.cos(a), 3 * np.sin(a), np.zeros(n)])
    goal = np.column_stack([3 * np.cos(a + 2.0), 3 * np.sin(a + 2.0), 2.0 + np.arange(n) * 0.7])
    d = av.Diagram()
    fleet = d.add(av.vehicles.velocity_controlled_quadrotor(av.vehicles.Quadrotor(start)),
                  name="fleet")
    drive = d.add(av.controllers.HolonomicPointToPoint(goal[:, None, :], gain=1.0, v_max=1.5,
                                                        radius=0.2), name="drive")
    d.connect(fleet.position, drive.position)
    d.connect(drive.velocity, fleet.velocity)
    res = av.simulate(d, 10.0, dt=0.01, log=[fleet.position, fleet.attitude], log_every=10)
    anim = av.viz.animate3d(res, trail=10.0)
    anim.update(len(anim) - 1)
    anim.fig.savefig(IMAGES / f"{name}.png", dpi=100)
    plt.close(anim.fig)


def _scenario(name):
    return lambda _picture: make(name)


#: picture name (docs/images/NAME.png) -> (what makes it, heavy?)
PRODUCERS = {
    **{f"scenario_{n}": (_scenario(n), False) for n in builtin_scenarios()},
    "plots_trajectories": (_page("plots-and-movies.md"), False),
    "plots_two_panels": (_page("plots-and-movies.md"), False),
    "plots_signals": (_page("plots-and-movies.md"), False),
    "lab1_integration_error": (_page("labs/lab1.md"), False),
    "lab2_look_ahead": (_page("labs/lab2.md"), False),
    "lab3_gains": (_page("labs/lab3.md"), False),
    "lab4_rings": (_page("labs/lab4.md"), False),
    "lab5_swap": (_page("labs/lab5.md"), False),
    "lab5_flock": (_page("labs/lab5.md"), False),
    "lab6_watchdog": (_page("labs/lab6.md"), False),
    # lab 7 trains its policy (about a minute) and runs it on the robot emulator
    **{f"lab7_{name}": (_page("labs/lab7.md"), False)
       for name in ("task", "training", "policy", "robots")},
    **{f"lab8_{name}": (_page("labs/lab8.md"), False)
       for name in ("dead_reckoning", "kalman", "nees")},
    "linear_formation_locus": (_page("linear-analysis.md"), False),
    "diagram": (draw_diagram_picture, False),
    "animation_frame": (draw_animation_frame, False),
    "uav3d": (draw_uav3d, False),
    "tune_gains": (_script([sys.executable, str(ROOT / "examples" / "06_tune_gains.py")],
                           made="tune_gains.png"), True),
    "robots-wiring": (_script([sys.executable, "docs/images/robots_wiring.py"]), False),
    "robots-formation-diagram": (_script([sys.executable, "docs/images/robots_wiring.py",
                                          "--formation"]), False),
    # the editor's screenshots: taken by its browser tests (system Chromium)
    **{f"editor-{shot}": (_script([sys.executable, "-m", "pytest", "-q", "-p",
                                   "no:cacheprovider", "tests/editor/test_browser.py"]), True)
       for shot in ("empty", "wired", "error", "run", "formation", "group",
                    "group-inside", "routing", "feedback-waypoints", "feedback-formation",
                    "plot", "tune")},
    # the drone case study in simulation, and flown on the emulators in real time
    "drones-formation-sim": (_script([sys.executable, "-m", "avblocks", "run",
                                      "drone_formation", "--out", "{tmp}", "--quiet"],
                                     made="paths.png"), True),
    "drones-formation-mavlink": (_script([sys.executable, "docs/images/drones_mavlink.py",
                                          "{images}/drones-formation-mavlink.png"]), True),
    # flown on the Crazyflie emulator in real time (about 80 s)
    "drones-formation-crazyflie": (_script([sys.executable, "docs/images/drones_crazyflie.py",
                                            "{images}/drones-formation-crazyflie.png"]), True),
    "scaling": (_script([sys.executable, "benchmarks/scaling.py",
                         "--out", "{images}/scaling.png"]), True),
    "scaling_backends": (_script([sys.executable, "benchmarks/scaling.py", "--backend", "jax",
                                  "--out", "{images}/scaling.png"]), True),
    "interacting": (_script([sys.executable, "benchmarks/interacting.py",
                             "--out", "{images}/interacting.png"]), True),
    # made on a GPU machine (the jax column runs on JAX's default device)
    "interacting_gpu": (_script([sys.executable, "benchmarks/interacting.py", "--n", "100",
                                 "1000", "10000", "100000", "1000000", "--engines",
                                 "jax,numba", "--rounds", "1", "--steps-scale", "10",
                                 "--out", "{images}/interacting_gpu.png"]), True),
    "tune_flocking": (_script([sys.executable, str(ROOT / "examples" / "10_tune_flocking.py")],
                              made="tune_flocking.png"), True),
    "physics-benchmark": (_script([sys.executable, "benchmarks/physics.py",
                                   "--png", "{images}/physics-benchmark.png"]), True),
    "live-formation": (_script([sys.executable, "docs/live_screenshots.py"]), True),
    "live-quadrotors": (_script([sys.executable, "docs/live_screenshots.py"]), True),
    "live-1000": (_script([sys.executable, "benchmarks/live.py", "--agents", "1000", "10000",
                           "--shots", "{images}"]), True),
    "live-10000": (_script([sys.executable, "benchmarks/live.py", "--agents", "1000", "10000",
                            "--shots", "{images}"]), True),
    "uav-tracking": (_script([sys.executable, "-m", "avblocks", "run", "uav_tracking",
                              "--out", "{tmp}", "--quiet"], made="tracking.mp4", frame=0.5),
                     True),
    "uav-tracking-error": (_script([sys.executable, "-m", "avblocks", "run", "uav_tracking",
                                    "--out", "{tmp}", "--quiet"], made="tracking_error.png"),
                           True),
    "soak": (_script([sys.executable, "benchmarks/soak.py", "--minutes", "30",
                      "--plot", "{images}/soak.png"]), True),
    "ppo_navigation": (_script([sys.executable, str(ROOT / "examples" / "08_ppo_navigation.py")],
                               made="ppo_navigation.png"), True),
    "apg_navigation": (_script([sys.executable, str(ROOT / "examples" / "09_apg_navigation.py")],
                               made="apg_navigation.png"), True),
    "rl_throughput": (_script([sys.executable, "benchmarks/rl_throughput.py",
                               "--plot", "{images}/rl_throughput.png"]), True),
    # made on a GPU machine, VMAS on CUDA (XLA_PYTHON_CLIENT_PREALLOCATE=false)
    "rl_throughput_gpu": (_script([sys.executable, "benchmarks/rl_throughput.py", "--sizes",
                                   "1", "64", "1024", "16384", "65536", "--vmas-device", "cuda",
                                   "--plot", "{images}/rl_throughput_gpu.png"]), True),
    "sweep_time_to_done": (_script([sys.executable, "-m", "avblocks", "sweep", "waypoints",
                                    "--grid", "drive.gain=0.5,1,2", "--grid",
                                    "drive.v_max=1,2,3", "--seeds", "4",
                                    "--out", "{tmp}/sweep.zarr"],
                                   made="sweep.zarr.time_to_done.png"), True),
}

_IMAGE_REF = re.compile(r"(?:\]\(|src=\")(?:\.\./)*(?:docs/)?images/([\w.-]+)\.png")


def referenced():
    """{picture name: [pages naming it]} over the README and docs/**/*.md."""
    out = {}
    for page in [ROOT / "README.md", *sorted(DOCS.rglob("*.md"))]:
        for m in _IMAGE_REF.finditer(page.read_text()):
            out.setdefault(m.group(1), []).append(str(page.relative_to(ROOT)))
    return out


def check() -> list[str]:
    """What is wrong between the pages, :data:`PRODUCERS` and docs/images."""
    refs = referenced()
    problems = [f"{name}.png (named by {', '.join(pages)}) is made by nothing in PRODUCERS"
                for name, pages in sorted(refs.items()) if name not in PRODUCERS]
    problems += [f"{name}.png is made here but no page names it"
                 for name in sorted(PRODUCERS) if name not in refs
                 and not name.startswith("scenario_")]
    problems += [f"{p.name} is in docs/images but made by nothing here"
                 for p in sorted(IMAGES.glob("*.png")) if p.stem not in PRODUCERS]
    problems += [f"{name}.png is named by a page but missing from docs/images"
                 for name in sorted(refs) if not (IMAGES / f"{name}.png").is_file()]
    return problems


def produce(names):
    done = set()
    for name in names:
        fn, _ = PRODUCERS[name]
        if fn in done:
            continue
        done.add(fn)
        fn(name) if fn.__code__.co_argcount else fn()
        print(f"made {name}")


if __name__ == "__main__":
    args = sys.argv[1:]
    if args == ["--list"]:
        for name, (fn, heavy) in PRODUCERS.items():
            print(f"{name:28s} {'heavy' if heavy else 'quick'}  {fn.__name__}")
    elif args == ["--check"]:
        problems = check()
        print("\n".join(problems) or "every picture is made here and named by a page")
        sys.exit(1 if problems else 0)
    elif args == ["--all"]:
        produce(list(PRODUCERS))
    elif args == ["--docs"]:
        produce(["plots_trajectories"])
    else:
        produce(args or [n for n, (_, heavy) in PRODUCERS.items() if not heavy])
