"""rmw_zenoh topics and services for the Crazyflie types.

Topics reuse :class:`avblocks.interfaces.ros2.Link` (key
``<domain>/<topic>/<DDS type>/<RIHS01 hash>``, attachment, liveliness
tokens) with the hashes of :mod:`._types`. Services follow the rmw_zenoh
design document:

* a **server** declares a *complete* queryable on
  ``<domain>/<service>/<DDS service type>/<service type hash>`` and a
  liveliness token of kind ``SS``; it answers each query with the response
  CDR and an attachment carrying the request's sequence number, a new
  source timestamp and the request's client GID;
* a **client** sends ``get`` on that key with target ``ALL_COMPLETE``, no
  consolidation, the request CDR as payload and an attachment (sequence
  number int64 LE, source timestamp int64 LE ns, GID length byte + 16-byte
  GID), and declares a liveliness token of kind ``SC``.
"""

from __future__ import annotations

import secrets
import struct
import threading
import time

from ..ros2._zenoh import QOS_TOKEN, Link, _mangle, _zenoh
from . import _types


class NoReply(Exception):
    """Raised by a service handler that must not answer at all (an
    emulated vehicle that is gone): the client's query ends unanswered."""


def attachment(seq, gid, stamp_ns=None):
    """rmw_zenoh attachment bytes."""
    return (struct.pack("<qq", int(seq), time.time_ns() if stamp_ns is None else stamp_ns)
            + bytes([len(gid)]) + bytes(gid))


def parse_attachment(data):
    """``(sequence number, timestamp ns, gid bytes)`` of an attachment."""
    data = bytes(data)
    if len(data) < 17 or len(data) < 17 + data[16]:
        raise ValueError(f"rmw_zenoh attachment of {len(data)} bytes is too short")
    seq, ts = struct.unpack("<qq", data[:16])
    return seq, ts, data[17:17 + data[16]]


class CfLink(Link):
    """A :class:`~avblocks.interfaces.ros2.Link` (rmw_zenoh convention) that
    knows the Crazyflie types' hashes and speaks services."""

    def __init__(self, router="tcp/127.0.0.1:7447", *, domain=None, node="avblocks",
                 mode="client", session=None):
        _types.typestore()
        super().__init__(router, "rmw_zenoh", domain=domain, node=node, mode=mode,
                         session=session)
        self._queryables = []
        self._clients = []

    def key(self, topic, typename):
        return (f"{self.domain}/{topic.strip('/')}/{_types.dds_name(typename)}/"
                f"{_types.type_hash(typename)}")

    def _endpoint_token(self, kind, topic, typename):
        with self._lock:
            self._entity += 1
            ent = self._entity
        self._token(f"{kind}/%/{_mangle(self.namespace)}/{self.node}/{_mangle(topic)}/"
                    f"{_types.dds_name(typename)}/{_types.type_hash(typename)}/{QOS_TOKEN}",
                    ent)

    def serve(self, service_name, srvtype, handler):
        """Answer requests of ``srvtype`` on ``service_name``:
        ``handler(request dict)`` runs on Zenoh's thread; its return value
        (None: the empty response) is the response CDR."""
        key = self.key(service_name, srvtype)

        def on_query(query):
            try:
                seq, _, gid = parse_attachment(query.attachment.to_bytes())
            except Exception as e:  # noqa: BLE001 - a request without attachment
                query.reply_err(f"rmw_zenoh service request without a valid attachment: "
                                f"{e}".encode())
                return
            try:
                req = _types.decode_request(srvtype, query.payload.to_bytes())
                resp = handler(req)
            except NoReply:
                return
            except Exception as e:  # noqa: BLE001 - the client hears the failure
                query.reply_err(f"{type(e).__name__}: {e}".encode())
                return
            query.reply(query.key_expr, resp if resp is not None
                        else _types.empty_response(srvtype),
                        attachment=attachment(seq, gid))
        self._queryables.append(self.session.declare_queryable(key, on_query, complete=True))
        self._endpoint_token("SS", service_name, srvtype)

    def client(self, service_name, srvtype):
        """A :class:`ServiceClient` of ``srvtype`` on ``service_name``."""
        c = ServiceClient(self, service_name, srvtype)
        self._clients.append(c)
        self._endpoint_token("SC", service_name, srvtype)
        return c

    def close(self):
        for q in self._queryables:
            try:
                q.undeclare()
            except Exception:  # noqa: BLE001 - closing anyway
                pass
        self._queryables = []
        super().close()


class ServiceClient:
    """Calls one rmw_zenoh service (see the module docstring)."""

    def __init__(self, link, service_name, srvtype):
        self.link, self.name, self.srvtype = link, service_name, srvtype
        self.key = link.key(service_name, srvtype)
        self.gid = secrets.token_bytes(16)
        self._seq = 0
        self._lock = threading.Lock()

    def send(self, timeout=2.0, **fields):
        """Send a request now; returns a :class:`Pending` reply."""
        z = _zenoh()
        with self._lock:
            self._seq += 1
            seq = self._seq
        pending = Pending(self, seq)
        self.link.session.get(
            self.key, z.handlers.Callback(pending._on_reply, pending._on_end),
            target=z.QueryTarget.ALL_COMPLETE,
            consolidation=z.ConsolidationMode.NONE, timeout=float(timeout),
            payload=_types.request(self.srvtype, **fields),
            attachment=attachment(seq, self.gid))
        return pending

    def call(self, timeout=2.0, **fields):
        """Send a request and wait for the reply (see :meth:`Pending.wait`)."""
        return self.send(timeout, **fields).wait()


class Pending:
    """A request on its way; :meth:`wait` gives ``(ok, why)``.

    Zenoh calls :meth:`_on_reply` for each reply and :meth:`_on_end` once
    the query is over (every queryable answered, or its timeout); the first
    decisive outcome is kept, so any number of threads may wait on one
    request and all see the same answer (two threads reading one reply
    channel, as before, left the loser reporting "no reply" for a request
    the server had answered).
    """

    def __init__(self, client, seq):
        self.client, self.seq = client, seq
        self.result = None
        self._why = f"no reply from service '{client.name}' (nobody serves it?)"
        self._done = threading.Event()
        self._lock = threading.Lock()

    def _set(self, result):
        with self._lock:
            if self.result is None:
                self.result = result
        self._done.set()

    def _on_reply(self, reply):
        try:
            if reply.ok is None:
                self._why = (f"service '{self.client.name}' answered an error: "
                             f"{reply.err.payload.to_bytes().decode(errors='replace')}")
                return
            att = reply.ok.attachment
            if att is None:         # rmw_zenoh always attaches one: not an answer
                self._why = (f"a reply of service '{self.client.name}' without the rmw_zenoh "
                             "attachment (ignored)")
                return
            seq, _, gid = parse_attachment(att.to_bytes())
        except Exception:  # noqa: BLE001 - a malformed reply counts for nothing
            self._why = (f"a reply of service '{self.client.name}' with a malformed "
                         "attachment (ignored)")
            return
        if seq == self.seq and gid == self.client.gid:
            self._set((True, None))
        else:
            self._why = f"reply of service '{self.client.name}' for another request"

    def _on_end(self):
        self._set((False, self._why))

    def done(self):
        """True once the outcome is known."""
        return self._done.is_set()

    def wait(self, timeout=None):
        """``(True, None)`` once a reply with our sequence number and GID
        arrived; ``(False, reason)`` for an error reply or none before the
        request's timeout; ``(False, "... yet")`` if ``timeout`` seconds
        from now passed first (the request goes on: wait again)."""
        if self._done.wait(timeout):
            return self.result
        return False, f"no reply from service '{self.client.name}' yet"
