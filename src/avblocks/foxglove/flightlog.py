"""Reading the JSON-lines flight log of ``--robots mavlink|crazyflies``.

A flight log is a file someone else may have made (a colleague's flight,
a log sent with a bug report): it is read as data only, within limits
(size of the file, length of a line, nesting), and each record is checked
before it is used. A line that is not a JSON object with an ``ev`` name
and a ``wall`` time, or a set-point whose ``v`` is not a list of
three-number rows, is an :class:`AvError` naming the file and the line.

The records the drone fleets write (``interfaces.flight.fleet.Fleet.record``):
``start`` (``vehicles``), ``phase`` (``phase``, sometimes ``position``),
``preflight_ok``, ``preflight_refused`` (``reasons``), ``cmd`` (``t``: the
simulated time of the step, ``v``: the velocity set-points sent, (N, 3)
m/s, world ENU), ``failsafe`` (``reason``, ``vehicles``, ``action``),
``abort`` (``error``), ``land_timeout`` (``flying``), ``end``; each with
``wall`` (Unix time [s]). Other records are kept as they are.
"""

from __future__ import annotations

import json
import os
import stat
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.errors import AvError

#: largest flight log read [bytes]
MAX_BYTES = 512 * 1024**2
#: longest line [bytes]
MAX_LINE = 1024**2
#: deepest nesting of a record
MAX_DEPTH = 16


@dataclass
class FlightLog:
    """A flight log, read and checked.

    Attributes
    ----------
    events : list of dict
        Every record in file order.
    vehicles : list of str
        The names of the ``start`` record (empty if none).
    t : ndarray (K,)
        Simulated times of the ``cmd`` records [s].
    setpoints : ndarray (K, N, 3)
        Their velocity set-points [m/s].
    wall_offset : float or None
        ``wall - t`` of the set-points (median): maps a record's wall time
        to the run's time; None without set-points.
    """

    events: list
    vehicles: list = field(default_factory=list)
    t: np.ndarray = None
    setpoints: np.ndarray = None
    wall_offset: float | None = None

    def run_time(self, rec) -> float | None:
        """The run's time of record ``rec`` (its ``t``, else its wall time
        moved by :attr:`wall_offset`), or None when it cannot be placed."""
        if isinstance(rec.get("t"), (int, float)):
            return float(rec["t"])
        if self.wall_offset is None:
            return None
        return float(rec["wall"]) - self.wall_offset


def _depth(v, d=0):
    if d > MAX_DEPTH:
        return d
    if isinstance(v, dict):
        return max([_depth(x, d + 1) for x in v.values()] + [d + 1])
    if isinstance(v, list):
        return max([_depth(x, d + 1) for x in v] + [d + 1])
    return d


def _number(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v)


def read_flight_log(path, *, max_bytes=MAX_BYTES) -> FlightLog:
    """Read and check the flight log at ``path`` (see the module docstring).

    Raises
    ------
    AvError
        Not a regular file, larger than ``max_bytes``, a line longer than
        :data:`MAX_LINE` or nested deeper than :data:`MAX_DEPTH`, not JSON,
        or a record without the fields it must have.
    """
    path = Path(path)
    try:
        # no blocking on a FIFO, no following a link: check what was opened
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0)
                     | getattr(os, "O_NONBLOCK", 0))
    except OSError as e:
        raise AvError(f"cannot open the flight log '{path}': {e.strerror or e}") from None
    st = os.fstat(fd)
    if not stat.S_ISREG(st.st_mode):
        os.close(fd)
        raise AvError(f"the flight log '{path}' is not a regular file")
    if st.st_size > max_bytes:
        os.close(fd)
        raise AvError(f"the flight log '{path}' is too large",
                      expected=f"<= {max_bytes} bytes", found=st.st_size)
    with os.fdopen(fd, "rb") as f:
        events = []
        for n, line in enumerate(iter(lambda: f.readline(MAX_LINE + 1), b""), start=1):
            if len(line) > MAX_LINE:
                raise AvError(f"{path}:{n}: line longer than {MAX_LINE} bytes")
            if not line.strip():
                continue
            try:
                rec = json.loads(line)
            except (ValueError, RecursionError) as e:
                raise AvError(f"{path}:{n}: not JSON: {e}") from None
            if not isinstance(rec, dict) or not isinstance(rec.get("ev"), str) \
                    or not _number(rec.get("wall")):
                raise AvError(f"{path}:{n}: a flight-log record is a JSON object with "
                              "'ev' (text) and 'wall' (a number)", found=line[:80])
            if _depth(rec) > MAX_DEPTH:
                raise AvError(f"{path}:{n}: nested deeper than {MAX_DEPTH}")
            events.append(rec)
    log = FlightLog(events)
    for rec in events:
        if rec["ev"] == "start" and isinstance(rec.get("vehicles"), list):
            log.vehicles = [str(v) for v in rec["vehicles"]]
            break
    ts, vs = [], []
    for k, rec in enumerate(events):
        if rec["ev"] != "cmd":
            continue
        v = rec.get("v")
        ok = _number(rec.get("t")) and isinstance(v, list) and v and all(
            isinstance(r, list) and len(r) == 3 and all(_number(c) for c in r) for r in v)
        if not ok or (vs and len(v) != len(vs[0])):
            raise AvError(f"{path}: set-point record {k + 1} is malformed",
                          expected="{'ev': 'cmd', 't': number, 'v': [[vx, vy, vz], ...]} "
                                   "with one row per vehicle", found=str(rec)[:100])
        ts.append(float(rec["t"]))
        vs.append(v)
    if ts:
        log.t = np.asarray(ts)
        log.setpoints = np.asarray(vs, dtype=float)
        walls = np.asarray([r["wall"] for r in events if r["ev"] == "cmd"], float)
        log.wall_offset = float(np.median(walls - log.t))
    else:
        log.t = np.zeros(0)
        log.setpoints = np.zeros((0, len(log.vehicles), 3))
    return log
