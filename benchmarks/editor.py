"""Benchmark: the editor's validation round trip (a document in, its errors
and signal shapes out) for the built-in case studies and a 500-block document.

Run: ``python benchmarks/editor.py [--repeat 20]``. Prints a markdown table
of the median and best milliseconds per validation, in process
(``EditorService.validate``) and over HTTP on loopback (the JSON request of
the page, through uvicorn), and what the piece-by-piece pass costs (blocks
one by one, wires one by one, undriven inputs: the extra work a document
with an error takes to have every error found), and a layout-only edit (a
block moved: the scenario is unchanged, the findings are remembered).
Target of issue 31: a case study under 100 ms. Not part of the test suite.
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
import urllib.request


def big_document(n_blocks=500, agents=15):
    """A valid document of ``n_blocks`` blocks: teams of a Unicycle fleet
    driven by a PointToPoint law, laid out on a grid (also the 500-block
    document of the front end's frame-rate benchmark)."""
    blocks, wires, layout = {}, [], {}
    for i in range(n_blocks // 2):
        f, c = f"fleet{i}", f"drive{i}"
        blocks[f] = {"type": "vehicles.Unicycle",
                     "pose0": {"random_poses": {"n": "$agents", "area": [50, 50],
                                                "seed": i}}}
        blocks[c] = {"type": "controllers.PointToPoint", "n": "$agents",
                     "waypoints": {"random_waypoints": {"n": "$agents", "count": 2,
                                                        "area": [50, 50], "seed": i}}}
        wires += [[f"{f}.pose", f"{c}.pose"], [f"{c}.cmd", f"{f}.cmd"]]
        row, col = divmod(i, 10)
        layout[f] = [col * 560, row * 160]
        layout[c] = [col * 560 + 260, row * 160]
    return {"name": "big", "parameters": {"agents": agents, "seed": 1},
            "blocks": blocks, "wires": wires,
            "simulation": {"t_final": 10, "dt": 0.05}, "editor": {"layout": layout}}


def _time(fn, repeat):
    fn()                                            # warm: imports, caches
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        ts.append(1e3 * (time.perf_counter() - t0))
    return statistics.median(ts), min(ts)


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeat", type=int, default=20)
    ap.add_argument("--cases", nargs="*",
                    default=["formation", "nest", "flocking", "swap", "waypoints"])
    args = ap.parse_args()
    import os

    from avblocks.editor.server import EditorServer
    from avblocks.editor.service import EditorService, _Collector
    root = tempfile.mkdtemp()
    service = EditorService(root)
    docs = [(n, service.load(builtin=n)["document"]) for n in args.cases]
    docs.append(("500 blocks", big_document()))
    print(f"load average {os.getloadavg()[0]:.2f}, {os.cpu_count()} CPUs, "
          f"{args.repeat} repeats")
    print()
    print("| document | blocks | ok | in process median ms | best | HTTP median ms | best "
          "| piece by piece median ms | layout-only edit median ms |")
    print("|---|---|---|---|---|---|---|---|---|")
    with EditorServer(service) as srv:
        for name, doc in docs:
            body = json.dumps({"document": doc}).encode()

            def over_http(body=body):
                service._checked.clear()        # measure a build, not a remembered one
                req = urllib.request.Request(srv.url + "api/validate", data=body,
                                             method="POST",
                                             headers={"content-type": "application/json"})
                with urllib.request.urlopen(req) as r:
                    return json.loads(r.read())

            ok = service.validate(doc)["ok"]

            def in_process(doc=doc):
                service._checked.clear()
                return service.validate(doc)

            def layout_only(doc=doc):               # a block moved: remembered
                moved = dict(doc, editor={"layout": {"x": [time.perf_counter(), 0]}})
                return service.validate(moved)

            med, best = _time(in_process, args.repeat)
            lmed, _ = _time(layout_only, args.repeat)
            hmed, hbest = _time(over_http, args.repeat)

            def pieces(doc=doc):        # what a document with an error costs
                data = {k: v for k, v in doc.items() if k != "editor"}
                c = _Collector(data, str(service.root / "x.yaml"), service.root / "o")
                d = c.blocks()
                c.wires(d)
                d.unconnected_inputs()

            pmed, _ = _time(pieces, max(3, args.repeat // 2))
            print(f"| {name} | {len(doc['blocks'])} | {ok} | {med:.1f} | {best:.1f} "
                  f"| {hmed:.1f} | {hbest:.1f} | {pmed:.1f} | {lmed:.2f} |")


if __name__ == "__main__":
    main()
