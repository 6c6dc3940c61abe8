"""Train lab 7's reference policy and embed it in ``solutions/lab7_learning.py``.

    python tests/labs/train_lab7_policy.py [--updates 300] [--seed 0]

What a student does on the lab page, with the reference solution's own
``observe`` and ``reward``: ``training_task`` (the navigation task of 3
agents whose observation and reward are those functions),
``rl.ppo.train`` with the lab's settings (``lab7_learning.ppo_config``),
then ``embed_policy`` writes the actor's weights into the solution file
(between ``POLICY = \"\"\"`` and its closing quotes) and the lines above
it record the run (seed, updates, wall time, the success over the lab
check's fixed held-out episodes). The same weights go to
``src/avblocks/labs/data/lab7_policy.npz`` (``lab7_learning.example_policy``),
which the lab page loads instead of training when ``AVBLOCKS_EXAMPLE_SMALL``
is set (the docs' tests). ``tests/labs/test_lab7.py`` checks that the two
hold the same weights, the network the lines describe, and that they pass
the check (the reference solution's run).
"""

from __future__ import annotations

import argparse
import importlib.util
import re
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SOLUTION = HERE / "solutions" / "lab7_learning.py"


def load_solution():
    spec = importlib.util.spec_from_file_location("lab7_reference", SOLUTION)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def main(argv=None):
    from avblocks import rl
    from avblocks.labs import lab7_learning as lab
    from avblocks.rl import ppo
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--updates", type=int, default=300)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    sol = load_solution()
    env = rl.functional(lab.training_task(sol.observe, sol.reward))
    t0 = time.perf_counter()
    res = ppo.train(env, lab.ppo_config(updates=args.updates), seed=args.seed)
    wall = time.perf_counter() - t0
    runs = lab.run_policy(res.actor, range(1000, 1000 + lab.EPISODES))
    rate = float(np.mean([np.asarray(r["task.success"])[-1] for r in runs]))
    n = lab.embed_policy(res.actor, SOLUTION)
    lab.EXAMPLE_POLICY.parent.mkdir(exist_ok=True)
    np.savez_compressed(lab.EXAMPLE_POLICY, **lab.decode_policy(lab.encode_policy(res.actor)))
    note = (f"# Trained by tests/labs/train_lab7_policy.py --updates {args.updates} --seed "
            f"{args.seed}:\n# {n} parameters, {wall:.0f} s of training; {rate:.1%} over the "
            f"check's {lab.EPISODES} fixed held-out episodes.\n")
    text = SOLUTION.read_text()
    text = re.sub(r"^# (The trained weights|Trained by).*?(?=^POLICY = )", lambda m: note, text,
                  count=1, flags=re.M | re.S)
    SOLUTION.write_text(text)
    print(note)


if __name__ == "__main__":
    main()
