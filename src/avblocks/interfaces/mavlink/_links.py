"""The emulator's side of a link: how PX4 SITL and ArduPilot SITL are reached.

* :class:`UdpVehiclePort` is PX4 SITL's offboard/API link
  (``ROMFS/px4fmu_common/init.d-posix/px4-rc.mavlink``: ``mavlink start -u
  $((14580+i)) -o $((14540+i)) -m onboard``): the vehicle owns UDP port
  14580+i and sends to 14540+i on the same host, where the ground side
  listens (``udpin:127.0.0.1:14540``); the first peer that sends to it
  becomes its partner (PX4 prints "partner IP"), and it answers there.
* :class:`TcpVehiclePort` is ArduPilot SITL's SERIAL0
  (``libraries/AP_HAL_SITL``: ``--serial0 tcp:0``, port 5760 + 10 i for
  instance i): a TCP server with one client at a time, which the ground
  side reaches with ``tcp:127.0.0.1:5760``.

Both bind 127.0.0.1 unless another address is named; both are
non-blocking: :meth:`read` returns what has arrived (``b""`` when
nothing), :meth:`write` sends or drops (a datagram link loses packets;
a TCP client that went away is forgotten).
"""

from __future__ import annotations

import errno
import select
import socket

_MAX = 65535


class UdpVehiclePort:
    """A vehicle's UDP port: bound to ``(host, port)``, sending to
    ``(host, remote)`` until a peer sends something, then to that peer."""

    def __init__(self, host, port, remote):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((host, int(port)))
        self.sock.setblocking(False)
        self.dest = (host, int(remote))
        self.partner = None

    def read(self):
        out = []
        while True:
            try:
                data, addr = self.sock.recvfrom(_MAX)
            except OSError as e:
                if e.errno in (errno.EAGAIN, errno.EWOULDBLOCK, errno.ECONNREFUSED):
                    break
                raise
            if self.partner is None:
                self.partner = addr
                self.dest = addr
            out.append(data)
        return b"".join(out)

    def write(self, buf):
        try:
            self.sock.sendto(buf, self.dest)
        except OSError:       # nobody listening there yet: the datagram is lost
            pass

    def close(self):
        self.sock.close()


class TcpVehiclePort:
    """A vehicle's TCP server (one client at a time, the next one accepted
    when it leaves)."""

    def __init__(self, host, port):
        self.srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.srv.bind((host, int(port)))
        self.srv.listen(1)
        self.srv.setblocking(False)
        self.client = None

    def _accept(self):
        if self.client is None:
            try:
                c, _ = self.srv.accept()
            except OSError:
                return
            c.settimeout(0.2)          # writes wait a little for a full buffer
            c.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self.client = c

    def read(self):
        self._accept()
        if self.client is None:
            return b""
        out = []
        while select.select([self.client], [], [], 0)[0]:
            try:
                data = self.client.recv(_MAX)
            except OSError:
                data = b""
            if not data:                  # the client left
                self._drop()
                break
            out.append(data)
        return b"".join(out)

    def _drop(self):
        try:
            self.client.close()
        finally:
            self.client = None

    def write(self, buf):
        if self.client is None:
            return
        try:
            self.client.sendall(buf)
        except OSError:
            self._drop()

    def close(self):
        if self.client is not None:
            self._drop()
        self.srv.close()
