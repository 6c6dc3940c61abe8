"""The commander's UDP link to one vehicle, locked to that vehicle.

pymavlink's own ``udpin`` connection takes every datagram from every
address, adds each sender to the set of peers it sends everything to, and
binds with ``SO_REUSEADDR`` (pymavlink 2.4, ``mavutil.mavudp``). On a
network anyone can reach, that lets any host

* feed the commander positions, acknowledgements, parameters and status
  texts in the vehicle's name (the message's system id is all it checks);
* make the commander send every set-point and command to as many addresses
  as it has source ports (measured: from 20 to 2 set-points a second with
  one sender cycling through source ports on loopback);
* and a second commander started on the same port steal the first one's
  telemetry (Linux delivers a unicast datagram to one of the sockets that
  share a port), so the first lands its vehicles as silent while the
  second takes them over in the air.

:class:`UdpLink` is the small replacement the commander uses for
``udpin:`` (``udp:``) and ``udpout:`` strings: a socket bound without
``SO_REUSEADDR`` (a port already in use is an error naming it), one peer:
for ``udpin`` the address of the first datagram that carries an autopilot's
HEARTBEAT (component 1, autopilot not ``MAV_AUTOPILOT_INVALID``, not a
ground station: PX4 SITL sends from 14580 + i), for ``udpout`` the address
named; datagrams from any other address are dropped before they are parsed
(counted in :attr:`foreign`), and nothing is sent anywhere else. It offers
what :class:`~.drones.MavlinkLink` uses of a pymavlink connection:
``recv_match(blocking, timeout)``, ``mav`` (the encoder whose
``*_send`` methods write to the peer) and ``close()``.

A host that spoofs the vehicle's own address (raw sockets on the same
network) is not stopped by this: MAVLink message signing would be needed
(see docs/security.md).
"""

from __future__ import annotations

import collections
import select
import socket

_MAX = 65535
#: MAV_TYPE_GCS and MAV_AUTOPILOT_INVALID, MAV_COMP_ID_AUTOPILOT1 (common.xml)
_TYPE_GCS, _AUTOPILOT_INVALID, _COMP_AUTOPILOT1 = 6, 8, 1


def parse_udp(spec):
    """``("in" | "out", host, port)`` of ``udpin:HOST:PORT`` / ``udp:HOST:PORT``
    / ``udpout:HOST:PORT``; ValueError naming what is wrong."""
    kind, _, rest = spec.partition(":")
    host, sep, port = rest.rpartition(":")
    if kind not in ("udpin", "udp", "udpout") or not sep or not host:
        raise ValueError("a UDP link is udpin:HOST:PORT or udpout:HOST:PORT")
    if not port.isdigit() or not 0 < int(port) < 65536:
        raise ValueError(f"port {port!r} is not a number from 1 to 65535")
    return ("out" if kind == "udpout" else "in"), host, int(port)


class UdpLink:
    """One vehicle over UDP (see the module docstring).

    Parameters
    ----------
    spec : str
        ``udpin:HOST:PORT`` (listen; the vehicle sends here) or
        ``udpout:HOST:PORT`` (send there; its answers come back).
    dialect : module
        pymavlink's generated dialect (``pymavlink.dialects.v20.common``).
    source_system, source_component : int
        The commander's MAVLink ids.
    """

    def __init__(self, spec, dialect, *, source_system=255, source_component=190):
        kind, host, port = parse_udp(spec)
        self.spec, self.kind = spec, kind
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            if kind == "in":
                self.sock.bind((host, port))        # no SO_REUSEADDR: one owner
                self.peer = None
            else:
                self.peer = (socket.gethostbyname(host), port)
        except BaseException:
            self.sock.close()
            raise
        self.sock.setblocking(False)
        self.d = dialect
        self.mav = dialect.MAVLink(self, srcSystem=source_system,
                                   srcComponent=source_component)
        self._parser = dialect.MAVLink(None)
        self._parser.robust_parsing = True
        self._probe = dialect.MAVLink(None)
        self._probe.robust_parsing = True
        self._queue = collections.deque()
        #: Datagrams dropped because they came from another address.
        self.foreign = 0
        #: The last few addresses they came from (at most 8).
        self.foreign_from = collections.OrderedDict()

    # -------------------------------------------------------------- sending
    def write(self, buf):
        """pymavlink's encoder writes here: to the peer only (nothing
        before the vehicle is known)."""
        if self.peer is None:
            return
        try:
            self.sock.sendto(bytes(buf), self.peer)
        except OSError:         # a full buffer, an unreachable port: a lost datagram
            pass

    # -------------------------------------------------------------- receiving
    def _from_autopilot(self, data):
        """Does this datagram carry an autopilot's HEARTBEAT?"""
        try:
            msgs = self._probe.parse_buffer(data) or []
        except Exception:  # noqa: BLE001 - not MAVLink
            return False
        finally:
            self._probe = self.d.MAVLink(None)     # no bytes kept between datagrams
            self._probe.robust_parsing = True
        return any(m.get_type() == "HEARTBEAT" and m.get_srcComponent() == _COMP_AUTOPILOT1
                   and m.type != _TYPE_GCS and m.autopilot != _AUTOPILOT_INVALID
                   for m in msgs)

    def _foreign(self, addr):
        self.foreign += 1
        self.foreign_from[addr] = self.foreign_from.get(addr, 0) + 1
        self.foreign_from.move_to_end(addr)
        while len(self.foreign_from) > 8:
            self.foreign_from.popitem(last=False)

    def _read(self):
        """Read the waiting datagrams (at most 256: a flood must not keep
        the receiver here) and queue the peer's messages."""
        for _ in range(256):
            try:
                data, addr = self.sock.recvfrom(_MAX)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:          # ICMP port unreachable and the like
                return
            if self.peer is None:
                if not self._from_autopilot(data):
                    continue          # before the vehicle is known: nothing else counts
                self.peer = addr
            elif addr != self.peer:
                self._foreign(addr)
                continue
            try:
                self._queue.extend(m for m in (self._parser.parse_buffer(data) or [])
                                   if m is not None)
            except Exception:  # noqa: BLE001 - a datagram that breaks the parser
                self._parser = self.d.MAVLink(None)
                self._parser.robust_parsing = True

    def recv_match(self, blocking=False, timeout=None):
        """The next message of the vehicle (None after ``timeout`` s)."""
        if not self._queue:
            self._read()
        if not self._queue and blocking:
            try:
                select.select([self.sock], [], [], timeout)
            except (OSError, ValueError):    # closed meanwhile
                return None
            self._read()
        return self._queue.popleft() if self._queue else None

    def close(self):
        self.sock.close()
