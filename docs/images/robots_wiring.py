"""Draws docs/images/robots-wiring.png, or with ``--formation``
docs/images/robots-formation-diagram.png (run from the repository root)."""

import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch  # noqa: E402


def box(ax, x, y, w, h, title, lines=(), color="#e8eef8"):
    ax.add_patch(FancyBboxPatch((x, y), w, h, boxstyle="round,pad=0.02", fc=color,
                                ec="#334"))
    ax.text(x + w / 2, y + h - 0.12, title, ha="center", va="top", weight="bold", fontsize=10)
    for k, s in enumerate(lines):
        ax.text(x + w / 2, y + h - 0.42 - 0.22 * k, s, ha="center", va="top", fontsize=8,
                family="monospace")


def arrow(ax, a, b, text="", both=True):
    ax.add_patch(FancyArrowPatch(a, b, arrowstyle="<|-|>" if both else "-|>",
                                 mutation_scale=12, color="#334", lw=1.2))
    if text:
        ax.text((a[0] + b[0]) / 2, (a[1] + b[1]) / 2 + 0.08, text, ha="center",
                fontsize=8)


def wiring():
    fig, ax = plt.subplots(figsize=(10, 4.6))
    ax.set_xlim(0, 10)
    ax.set_ylim(0, 4.6)
    ax.axis("off")
    box(ax, 0.2, 1.2, 2.9, 2.3, "laptop: avblocks",
        ["controllers -> cmd (N,2)", "Robots block 'fleet'", "  pose, fresh, age",
         "simulate(realtime=1)", "Zenoh client"])
    box(ax, 3.8, 1.7, 1.9, 1.3, "Zenoh router", ["tcp/<ip>:7447"], color="#f6eedd")
    for k, nm in enumerate(("tb1", "tb2", "tb3")):
        y = 3.25 - 1.35 * k
        box(ax, 6.5, y, 3.3, 1.15, f"robot {nm}",
            [f"/{nm}/cmd_vel  Twist  (in)", f"/{nm}/odom     Odometry (out)",
             "zenoh-bridge-ros2dds | rmw_zenoh"], color="#e9f5e9")
        arrow(ax, (5.75, 2.35), (6.45, y + 0.55))
    arrow(ax, (3.15, 2.35), (3.75, 2.35), "Zenoh")
    ax.text(5.0, 0.25, "keys: bridge 'tb1/cmd_vel'  |  rmw_zenoh "
            "'0/tb1/cmd_vel/geometry_msgs::msg::dds_::Twist_/RIHS01_...'",
            ha="center", fontsize=8, family="monospace")
    fig.tight_layout()
    fig.savefig("docs/images/robots-wiring.png", dpi=110)



def formation_on_robots():
    """docs/images/robots-formation-diagram.png: the formation case study's
    diagram with its vehicle model swapped for ``Robots`` (nothing is
    connected: a Robots block opens its session only when a run starts)."""
    from avblocks.interfaces.ros2 import replace_block, robots_like
    from avblocks.scenarios import formation
    from avblocks.viz import draw_diagram
    d, _ = formation.make_diagram(agents=3)
    replace_block(d, "fleet", robots_like(d["fleet"].block, "tb1,tb2,tb3"))
    draw_diagram(d, "docs/images/robots-formation-diagram.png", engine="matplotlib")


if __name__ == "__main__":
    formation_on_robots() if "--formation" in sys.argv else wiring()
