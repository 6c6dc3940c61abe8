"""A Foxglove layout for the case studies: a simulated run and a flight side
by side.

:func:`case_study_layout` builds it with foxglove-sdk's layout classes
(:mod:`foxglove.layouts`): a 3-D view of both (frames ``sim/...`` and
``flight/...``, bodies, obstacles, links, set-point arrows), plots of the
first agents' positions in both files and of the flight's set-points, and
the log (outcomes, flight events). ``layouts/case_studies.json`` in this
package is that layout written out (``python -m avblocks.foxglove.layout``
rewrites it; a test checks it is current). In Foxglove: Layouts > Import
from file, then open the run's and the flight's ``.mcap`` files together.
"""

from __future__ import annotations

import json
from pathlib import Path

#: the shipped layout file
LAYOUT_FILE = Path(__file__).with_name("layouts") / "case_studies.json"


def case_study_layout(prefixes=("sim", "flight"), signal="fleet.position", agents=(0, 1)):
    """The layout (a :class:`foxglove.layouts.Layout`) for runs written with
    these ``prefixes``, plotting ``signal`` of ``agents`` (module doc)."""
    try:
        import foxglove.layouts as fl
    except ImportError as e:
        from ..core.errors import AvError
        raise AvError(f"building a Foxglove layout needs foxglove-sdk: {e}",
                      hint="pip install 'avblocks[foxglove]'") from None
    topics = {}
    for p in prefixes:
        for name in ("bodies", "world", "links", "setpoint_arrows"):
            topics[f"/{p}/{name}"] = fl.BaseRendererSceneUpdateTopicSettings(visible=True)
    scene = fl.ThreeDeePanel(title="3-D: simulation and flight", config=fl.ThreeDeeConfig(
        follow_tf="world", follow_mode="follow-none", topics=topics))
    series = []
    for p in prefixes:
        for a in agents:
            for c in ("x", "y", "z"):
                series.append(fl.PlotSeries(
                    value=f"/{p}/signals/{signal}.agents[{a}].{c}",
                    label=f"{p} {a} {c}", line_style="solid" if p == prefixes[0]
                    else "dashed"))
    plot = fl.PlotPanel(title=f"{signal}: simulation and flight",
                        config=fl.PlotConfig(paths=series, show_legend=True,
                                             x_axis_val="timestamp"))
    setpoints = fl.PlotPanel(title="velocity set-points sent (flight)", config=fl.PlotConfig(
        paths=[fl.PlotSeries(value=f"/{prefixes[-1]}/setpoint.agents[{a}].{c}",
                             label=f"set-point {a} {c}")
               for a in agents for c in ("x", "y", "z")],
        show_legend=True, x_axis_val="timestamp"))
    log = fl.LogPanel(title="outcome and flight events", config=fl.LogConfig())
    return fl.Layout(content=fl.SplitContainer(direction="row", items=[
        fl.SplitItem(proportion=3, content=scene),
        fl.SplitItem(proportion=2, content=fl.SplitContainer(direction="column", items=[
            fl.SplitItem(proportion=2, content=plot),
            fl.SplitItem(proportion=1, content=setpoints),
            fl.SplitItem(proportion=1, content=log)]))]))


def layout_json(**options) -> str:
    """:func:`case_study_layout` as the JSON text Foxglove imports (sorted keys)."""
    return json.dumps(json.loads(case_study_layout(**options).to_json()), indent=2,
                      sort_keys=True) + "\n"


if __name__ == "__main__":      # rewrite the shipped layout file
    LAYOUT_FILE.parent.mkdir(exist_ok=True)
    LAYOUT_FILE.write_text(layout_json())
    print(f"wrote {LAYOUT_FILE}")
