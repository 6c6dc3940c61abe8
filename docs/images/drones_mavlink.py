"""Make ``drones-formation-mavlink.png``: the drone_formation case study
flown with ``avblocks run ... --robots mavlink`` on five emulated PX4
vehicles (``avblocks mavlink emulate`` on UDP loopback, a subprocess,
reached as PX4 SITL is: ``udpin:127.0.0.1:BASE+``), its planned-against-
flown figure copied to the path given and its outcome numbers printed.

Usage: python docs/images/drones_mavlink.py OUT.png
"""

import json
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from avblocks.scenarios.drone_formation import start_positions

N = 5


def _free_base_port(n, start=25000):
    """A base port whose ``n`` successors are free UDP ports on loopback."""
    for base in range(start, 60000, 97):
        socks = []
        try:
            for k in range(n):
                s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                socks.append(s)
                s.bind(("127.0.0.1", base + k))
            return base
        except OSError:
            continue
        finally:
            for s in socks:
                s.close()
    raise RuntimeError("no free UDP ports on 127.0.0.1")


def main(png):
    base = _free_base_port(N)                   # the commander's ports (PX4: 14540+i)
    vport = _free_base_port(N, base + 40)       # the vehicles' own (PX4: 14580+i)
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "emulator.jsonl"
        em = subprocess.Popen([sys.executable, "-m", "avblocks", "mavlink", "emulate",
                               "--n", str(N), "--base-port", str(base),
                               "--vehicle-port", str(vport), "--log", str(log),
                               "--pose0", json.dumps(start_positions(N, 0.0).tolist())])
        try:
            t_end = time.monotonic() + 30
            while not (log.exists() and log.stat().st_size):
                if em.poll() is not None or time.monotonic() > t_end:
                    raise RuntimeError("the MAVLink emulator did not start")
                time.sleep(0.1)
            subprocess.run([sys.executable, "-m", "avblocks", "run", "drone_formation",
                            "--robots", "mavlink", "--mavlink-connect",
                            f"udpin:127.0.0.1:{base}+", "--out", str(Path(tmp) / "out")],
                           check=True)
            print(json.dumps(json.loads((Path(tmp) / "out" / "summary.json").read_text())
                             ["numbers"]))
        finally:
            em.terminate()
            em.wait(10)
        shutil.copyfile(Path(tmp) / "out" / "paths.png", png)


if __name__ == "__main__":
    main(sys.argv[1])
