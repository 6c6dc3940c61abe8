"""Robot middleware costs over real Zenoh on loopback (extra [ros2]).

1. Round trip, command out -> pose back: an echo robot in a second process
   answers every ``cmd_vel`` Twist at once with an Odometry whose twist
   carries the command back; we time ``put`` of the Twist to the arrival
   of the matching Odometry (CDR encode and decode included, both sides
   through rosbags). Median and 99th percentile over 2,000 round trips,
   for each key convention (zenoh-bridge-ros2dds names, rmw_zenoh keys
   with attachments). The router is a Zenoh session in this process.
2. Per-step cost of the Robots block at N = 1, 10, 50 robots while an
   emulator publishes every robot's odometry at 30 Hz: the time of one
   major step of (Constant -> Robots) minus the same step of (Constant ->
   Unicycle), i.e. what talking to N robots adds to a step (N Twist
   encodes and puts, one buffer snapshot). Median and p99 over 400 steps,
   unpaced.

Run: ``python benchmarks/robots.py``; prints markdown tables and writes
``benchmarks/robots.png``.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

import avblocks as av
from avblocks.interfaces.ros2 import Link, Robots, _msgs, open_router

ECHO = r"""
import sys, time
from avblocks.interfaces.ros2 import Link, _msgs
router, conv = sys.argv[1], sys.argv[2]
link = Link(router, conv, node="echo")
pub = link.publisher("tb1/odom", _msgs.ODOMETRY)
def on_cmd(data, now):
    lin, ang = _msgs.decode_twist(data)
    pub.put(_msgs.encode_odometry(0, 0, 0, 0, lin, ang, time.time()))
link.subscribe("tb1/cmd_vel", _msgs.TWIST, on_cmd)
print("ready", flush=True)
sys.stdin.read()
"""


def env():
    e = dict(os.environ)
    src = str(Path(__file__).resolve().parents[1] / "src")
    e["PYTHONPATH"] = src + os.pathsep + e.get("PYTHONPATH", "")
    return e


def round_trip(router, conv, count=2000):
    p = subprocess.Popen([sys.executable, "-c", ECHO, router, conv], env=env(),
                         stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "ready"
    link = Link(router, conv, node="bench")
    pub = link.publisher("tb1/cmd_vel", _msgs.TWIST)
    got = threading.Event()
    box = {}

    def on_odom(data, now):
        box["v"] = _msgs.decode_odometry(data)[4]
        box["t"] = time.perf_counter()
        got.set()
    link.subscribe("tb1/odom", _msgs.ODOMETRY, on_odom)
    time.sleep(0.5)
    rtt = []
    for k in range(count + 50):
        got.clear()
        v = float(k + 1)
        t0 = time.perf_counter()
        pub.put(_msgs.encode_twist((v, 0, 0), (0, 0, 0)))
        if not got.wait(1.0) or box["v"] != v:
            continue
        if k >= 50:
            rtt.append(box["t"] - t0)
    link.close()
    p.terminate()
    p.wait(10)
    return np.array(rtt)


def step_cost(router, n, steps=400):
    names = [f"r{i}" for i in range(n)]
    em = subprocess.Popen([sys.executable, "-m", "avblocks", "robots", "emulate", "--names",
                           ",".join(names), "--router", router, "--spacing", "1.0"],
                          env=env(), stdout=subprocess.PIPE, text=True)
    em.stdout.readline()
    time.sleep(1.0)
    cmd = np.tile([0.0, 0.0], (n, 1))

    def per_step(block, port):
        d = av.Diagram()
        c = d.add(av.blocks.Constant(cmd), name="c")
        f = d.add(block, name="fleet")
        d.connect(c.y, f.port(port))
        sim = av.Simulator(d, dt=0.02)
        sim.init()
        out = []
        for _ in range(steps):
            t0 = time.perf_counter()
            sim.step()
            out.append(time.perf_counter() - t0)
        sim.close()
        return np.array(out)
    try:
        rob = per_step(Robots(names, router=router, wait=20.0), "cmd")
        base = per_step(av.vehicles.Unicycle(np.zeros((n, 3))), "cmd")
    finally:
        em.terminate()
        em.wait(10)
    return rob, base


def main():
    _session, router = open_router()
    rows = []
    for conv in ("bridge", "rmw_zenoh"):
        r = round_trip(router, conv) * 1e3
        rows.append((conv, len(r), np.median(r), np.percentile(r, 99)))
    print("\nRound trip command -> pose (echo robot, loopback, one router)\n")
    print("| keys | samples | median [ms] | p99 [ms] |\n|---|---:|---:|---:|")
    for conv, k, med, p99 in rows:
        print(f"| {conv} | {k} | {med:.3f} | {p99:.3f} |")
    cost = []
    for n in (1, 10, 50):
        rob, base = step_cost(router, n)
        cost.append((n, np.median(rob) * 1e3, np.median(base) * 1e3,
                     (np.median(rob) - np.median(base)) * 1e3,
                     np.percentile(rob, 99) * 1e3))
    print("\nPer-step cost of the Robots block (emulator publishing 30 Hz odometry)\n")
    print("| robots | step with Robots, median [ms] | with Unicycle [ms] | "
          "middleware added [ms] | per robot [us] | step p99 [ms] |")
    print("|---:|---:|---:|---:|---:|---:|")
    for n, r, b, add, p99 in cost:
        print(f"| {n} | {r:.3f} | {b:.3f} | {add:.3f} | {1e3 * add / n:.0f} | {p99:.3f} |")
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(1, 2, figsize=(9, 3.4))
    ax[0].bar([r[0] for r in rows], [r[2] for r in rows], label="median")
    ax[0].bar([r[0] for r in rows], [r[3] - r[2] for r in rows], bottom=[r[2] for r in rows],
              alpha=0.4, label="to p99")
    ax[0].set_ylabel("round trip [ms]")
    ax[0].legend()
    ax[1].plot([c[0] for c in cost], [c[3] for c in cost], "o-")
    ax[1].set_xlabel("robots N")
    ax[1].set_ylabel("middleware cost per step [ms]")
    for a in ax:
        a.grid(alpha=0.3)
    fig.tight_layout()
    out = Path(__file__).with_name("robots.png")
    fig.savefig(out, dpi=110)
    print(f"\nwrote {out}")
    print(json.dumps({"round_trip": rows, "step": cost}, default=float))


if __name__ == "__main__":
    main()
