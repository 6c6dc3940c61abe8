"""Cost of each vehicle family per agent and step (RK4, constant command).

Run:  python benchmarks/vehicles.py [--steps 200] [--sizes 1000 100000]

Prints a markdown table of nanoseconds per agent-step, and checks that a
Quadrotor at N=10,000 costs at most 3x the unicycle's per-agent-step time
times the ratio of state sizes (13 / 3). Not a test: nothing here asserts.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import avblocks as av
from avblocks import vehicles as V


def _p(n, k=3):
    return np.random.default_rng(0).normal(size=(n, k))


FAMILIES = {
    # name: (factory n -> block or diagram, input port, command per agent, state size)
    "Unicycle": (lambda n: V.Unicycle(_p(n)), "cmd", [1.0, 0.3], 3),
    "Unicycle2": (lambda n: V.Unicycle2(_p(n), mass=1.0, inertia=0.1, lin_damping=0.1),
                  "wrench", [1.0, 0.1], 5),
    "DiffDrive": (lambda n: V.DiffDrive(_p(n), wheel_speed_max=20.0), "wheels",
                  [9.0, 11.0], 3),
    "Ackermann": (lambda n: V.Ackermann(_p(n)), "cmd", [1.0, 0.2], 3),
    "Ackermann (lag)": (lambda n: V.Ackermann(_p(n), steer_tau=0.2), "cmd", [1.0, 0.2], 4),
    "SingleIntegrator 3D": (lambda n: V.SingleIntegrator(_p(n), v_max=2.0), "velocity",
                            [1.0, 0.5, 0.1], 3),
    "DoubleIntegrator 3D": (lambda n: V.DoubleIntegrator(_p(n), a_max=2.0, v_max=3.0),
                            "accel", [1.0, 0.5, 0.1], 6),
    "Quadrotor (wrench)": (lambda n: V.Quadrotor(_p(n)), "wrench", [9.81, 0, 0, 0.001], 13),
    "Quadrotor (rotors)": (lambda n: V.Quadrotor(_p(n), input="rotors"), "rotors",
                           [2.45, 2.46, 2.45, 2.46], 13),
    "Quadrotor + VelocityControl": (
        lambda n: V.velocity_controlled_quadrotor(V.Quadrotor(_p(n))), "velocity",
        [1.0, 0.5, 0.0], 13),
    "Blimp": (lambda n: V.Blimp(_p(n)), "thrust", [0.3, 0.0, 0.01], 8),
}


def ns_per_agent_step(name, n, steps, dt=0.01):
    make, port, cmd, _ = FAMILIES[name]
    d = av.Diagram()
    v = d.add(make(n), name="v")
    c = d.add(av.blocks.Constant(np.tile(np.asarray(cmd, float), (n, 1))), name="c")
    d.connect(c.y, v.port(port))
    sim = av.Simulator(d, dt=dt, solver="rk4")
    sim.init()
    for _ in range(3):
        sim.step()
    t0 = time.perf_counter()
    for _ in range(steps):
        sim.step()
    wall = time.perf_counter() - t0
    return wall / (n * steps) * 1e9


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=200, help="steps at the smallest size")
    ap.add_argument("--sizes", type=int, nargs="+", default=[1_000, 100_000])
    args = ap.parse_args(argv)
    sizes = sorted(args.sizes)
    rows = {}
    for name in FAMILIES:
        rows[name] = []
        for n in sizes:
            # keep each cell to a few seconds: fewer steps for huge N
            steps = args.steps if n <= 10_000 else max(20, args.steps // 4)
            rows[name].append(ns_per_agent_step(name, n, steps))
    head = "| family | state | " + " | ".join(f"N={n:,} (ns/agent-step)" for n in sizes) + " |"
    print(head)
    print("|" + "---|" * (2 + len(sizes)))
    for name, vals in rows.items():
        cells = " | ".join(f"{v:,.1f}" for v in vals)
        print(f"| {name} | {FAMILIES[name][3]} | {cells} |")

    n = 10_000
    uni = ns_per_agent_step("Unicycle", n, args.steps)
    quad = ns_per_agent_step("Quadrotor (wrench)", n, args.steps)
    budget = 3 * uni * 13 / 3
    verdict = "within" if quad <= budget else "OVER"
    print(f"\nQuadrotor at N={n:,}: {quad:.1f} ns/agent-step; unicycle {uni:.1f}; "
          f"budget 3 x {uni:.1f} x 13/3 = {budget:.1f} -> {verdict} "
          f"(ratio {quad / uni:.2f}x vs state ratio {13 / 3:.2f})")


if __name__ == "__main__":
    main()
