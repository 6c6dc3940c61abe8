"""Make ``drones-formation-crazyflie.png``: the drone_formation case study
flown with ``avblocks run ... --robots crazyflies`` on five emulated
Crazyflies (a Zenoh router in this process, the emulator and the run as
subprocesses), its planned-against-flown figure copied to the path given.

Usage: python docs/images/drones_crazyflie.py OUT.png
"""

import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from avblocks.interfaces.ros2 import open_router
from avblocks.scenarios.drone_formation import start_positions


def main(png):
    session, ep = open_router()
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "emulator.jsonl"
        em = subprocess.Popen([sys.executable, "-m", "avblocks", "crazyflies", "emulate",
                               "--names", "cf1,cf2,cf3,cf4,cf5", "--router", ep, "--log",
                               str(log), "--position0",
                               json.dumps(start_positions(5, 0.0).tolist())])
        try:
            while not (log.exists() and log.stat().st_size):
                time.sleep(0.1)
            time.sleep(0.5)
            subprocess.run([sys.executable, "-m", "avblocks", "run", "drone_formation",
                            "--robots", "crazyflies", "--cf-router", ep, "--out",
                            str(Path(tmp) / "out")], check=True)
        finally:
            em.terminate()
            em.wait(10)
            session.close()
        end = [json.loads(s) for s in log.read_text().splitlines()][-1]
        print(f"emulator: lost {end.get('lost_s', 0):.2f} s to late ticks")
        num = json.loads((Path(tmp) / "out" / "summary.json").read_text())["numbers"]
        print("outcome: " + ", ".join(f"{k} {v:.3f}" for k, v in num.items()
                                      if isinstance(v, float)))
        shutil.copyfile(Path(tmp) / "out" / "paths.png", png)


if __name__ == "__main__":
    main(sys.argv[1])
