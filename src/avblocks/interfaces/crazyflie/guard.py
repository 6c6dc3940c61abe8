"""A guard process that lands Crazyflies whose commander died.

A Crazyflie streaming set-points falls about 2 s after its commander dies
(the firmware's set-point watchdog stops the motors; see
:mod:`.emulator`). Nothing on the vehicle or in Crazyswarm2 lands it. The
guard is a second, small process (run it beside the Crazyswarm2 server):

* it watches the Zenoh liveliness tokens by which a :class:`Crazyflies`
  block claims each vehicle (``avblocks/commander/<command key>/<session
  id>``, declared before the block sends anything) and the vehicles'
  ``/cfN/pose``;
* when a commander's token disappears (its session closed, or its process
  died: the router drops the token of a killed process when the TCP
  connection closes) and the vehicle is still above the floor
  (``z > floor + 0.05`` m, the floor being the lowest height seen),
  it calls ``land`` and then ``notify_setpoints_stop`` for it, as the
  block's own fail-safe does: within a fraction of the 0.5 s before the
  firmware would level the vehicle out.

After a normal end the block has landed the vehicles already; a ``land``
to a vehicle that is landing is ignored by the firmware (the planner
refuses a second landing), and one on the floor is not sent.
"""

from __future__ import annotations

import json
import threading
import time

import numpy as np

from ..ros2._zenoh import CLAIM_PREFIX
from . import _types
from ._link import CfLink


class Guard:
    """Lands the Crazyflies ``names`` when their commander disappears (see
    the module docstring).

    Parameters
    ----------
    names : list of str or "cf1,cf2"
    router : str
        Zenoh router endpoint.
    land_duration, land_height : float
        Of the landing it commands [s, m].
    domain : int, optional
        ROS domain id.
    log : path, optional
        JSON-lines log of what it saw and did.
    """

    def __init__(self, names, router="tcp/127.0.0.1:7447", *, land_duration=3.0,
                 land_height=0.0, domain=None, log=None):
        self.names = [s.strip() for s in (names.split(",") if isinstance(names, str)
                                          else names)]
        self.land_duration, self.land_height = float(land_duration), float(land_height)
        self._log = open(log, "a", buffering=1) if log else None
        self._lock = threading.Lock()
        n = len(self.names)
        self.z = np.full(n, np.nan)
        self.floor = np.full(n, np.inf)
        self.owners = {}                        # vehicle -> set of commander session ids
        self.link = link = CfLink(router, domain=domain, node="avblocks_guard")
        for i, nm in enumerate(self.names):
            link.subscribe(f"/{nm}/pose", _types.POSE_STAMPED,
                           lambda d, now, i=i: self._on_pose(i, d))
        self._land = [link.client(f"/{nm}/land", _types.LAND) for nm in self.names]
        self._notify = [link.client(f"/{nm}/notify_setpoints_stop", _types.NOTIFY)
                        for nm in self.names]
        self._prefixes = {}
        for nm in self.names:
            for topic, ptype in (("cmd_full_state", _types.FULL_STATE),
                                 ("cmd_velocity_world", _types.VELOCITY_WORLD)):
                self._prefixes[f"{CLAIM_PREFIX}/{link.key(f'/{nm}/{topic}', ptype)}/"] = nm
        self._sub = link.session.liveliness().declare_subscriber(
            f"{CLAIM_PREFIX}/**", self._on_token, history=True)
        self._stop = threading.Event()
        self.write({"ev": "start", "vehicles": self.names})

    def write(self, rec):
        if self._log is not None:
            with self._lock:
                self._log.write(json.dumps({"wall": time.time(), **rec}) + "\n")

    def _on_pose(self, i, data):
        try:
            z = _types.decode_pose(data)[2]
        except Exception:  # noqa: BLE001 - not a pose: ignore
            return
        if np.isfinite(z):
            self.z[i] = z
            self.floor[i] = min(self.floor[i], z)

    def _on_token(self, sample):
        key = str(sample.key_expr)
        hit = next(((p, nm) for p, nm in self._prefixes.items() if key.startswith(p)), None)
        if hit is None:
            return
        prefix, nm = hit
        zid = key[len(prefix):]
        import zenoh
        if sample.kind == zenoh.SampleKind.PUT:
            self.owners.setdefault(nm, set()).add(zid)
            self.write({"ev": "commander", "vehicle": nm, "session": zid})
            return
        self.owners.get(nm, set()).discard(zid)
        i = self.names.index(nm)
        flying = bool(np.isfinite(self.z[i]) and self.z[i] > self.floor[i] + 0.05)
        self.write({"ev": "commander_gone", "vehicle": nm, "session": zid,
                    "z": None if not np.isfinite(self.z[i]) else float(self.z[i]),
                    "flying": flying})
        if flying and not self.owners.get(nm):
            threading.Thread(target=self._land_one, args=(i,), daemon=True).start()

    def _land_one(self, i):
        ok1, why1 = self._land[i].send(1.0, height=self.land_height,
                                       duration=self.land_duration).wait(0.3)
        ok2, why2 = self._notify[i].call(1.0, remain_valid_millisecs=100)
        self.write({"ev": "landed_by_guard", "vehicle": self.names[i], "land": why1,
                    "notify": why2, "ok": bool(ok1 and ok2)})

    def run(self, duration=None):
        """Guard until :meth:`stop` (or ``duration`` seconds)."""
        self._stop.wait(duration)

    def stop(self):
        self._stop.set()

    def close(self):
        try:
            self._sub.undeclare()
        except Exception:  # noqa: BLE001 - closing anyway
            pass
        self.link.close()
        with self._lock:
            if self._log is not None:
                self._log.close()
                self._log = None


def main(args):
    """``avblocks crazyflies guard``."""
    import signal
    g = Guard(args.names, args.router, land_duration=args.land_duration,
              land_height=args.land_height, domain=args.domain, log=args.log)
    signal.signal(signal.SIGTERM, lambda *a: g.stop())
    print(f"guarding Crazyflies {','.join(g.names)} via {args.router}", flush=True)
    try:
        g.run(args.duration)
    except KeyboardInterrupt:
        pass
    finally:
        g.close()
    return 0


def add_parser(rs):
    """Add ``guard`` to the ``crazyflies`` command group."""
    g = rs.add_parser("guard", help="land Crazyflies whose avblocks commander dies "
                                    "(run beside the Crazyswarm2 server)")
    g.add_argument("--names", required=True, help="vehicle names, e.g. cf1,cf2,cf3")
    g.add_argument("--router", default="tcp/127.0.0.1:7447", help="Zenoh router endpoint")
    g.add_argument("--land-duration", type=float, default=3.0, dest="land_duration")
    g.add_argument("--land-height", type=float, default=0.0, dest="land_height")
    g.add_argument("--domain", type=int, default=None, help="ROS domain id")
    g.add_argument("--duration", type=float, help="seconds to run (default: forever)")
    g.add_argument("--log", help="JSON-lines log")
    g.set_defaults(fn=main)
    return g
