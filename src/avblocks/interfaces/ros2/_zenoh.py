"""Zenoh sessions and the two ROS 2 key conventions.

``bridge``
    what zenoh-bridge-ros2dds exposes: the ROS topic name without its
    leading slash is the key (``/tb1/cmd_vel`` -> ``tb1/cmd_vel``), the
    payload is the CDR message, no attachment.
``rmw_zenoh``
    ROS 2's own Zenoh middleware (rmw_zenoh_cpp, Jazzy and later): the key
    is ``<domain>/<topic>/<DDS type name>/<type hash>``
    (``0/tb1/cmd_vel/geometry_msgs::msg::dds_::Twist_/RIHS01_...``); each
    sample carries an attachment (sequence number, source timestamp in ns,
    16-byte publisher GID; the GID length-prefixed with one byte); and the
    node, its publishers and subscriptions declare liveliness tokens under
    ``@ros2_lv/<domain>/...`` so that ``ros2 node list`` and
    ``ros2 topic list`` on a machine running rmw_zenoh see them.

Everything here follows the public rmw_zenoh design document; the code is
our own. A session is a Zenoh *client* of a router (``tcp/127.0.0.1:7447``
by default, what ``ros2 run rmw_zenoh_cpp rmw_zenohd`` or a
zenoh-bridge-ros2dds listens on) and listens on nothing itself.
"""

from __future__ import annotations

import os
import secrets
import socket
import struct
import threading
import time

from ...core.errors import ParameterError
from . import _msgs

CONVENTIONS = ("bridge", "rmw_zenoh")
#: QoS written in liveliness tokens: reliable, volatile, keep last 10
#: (rmw_zenoh's encoding ``<rel>:<dur>:<hist>,<depth>:<deadline>:<lifespan>:<liveliness>``).
QOS_TOKEN = "1:2:1,10:,:,:,,"
#: Liveliness tokens that say which session commands a robot (see ``Link.claim``).
CLAIM_PREFIX = "avblocks/commander"


def _zenoh():
    try:
        import zenoh
    except ImportError as e:  # pragma: no cover - the [ros2] extra
        raise ParameterError("talking to robots needs the 'eclipse-zenoh' package",
                             hint="pip install 'avblocks[ros2]'") from e
    return zenoh


def _config(mode, connect=(), listen=()):
    zenoh = _zenoh()
    c = zenoh.Config()
    c.insert_json5("mode", f'"{mode}"')
    c.insert_json5("connect/endpoints", _json_list(connect))
    c.insert_json5("listen/endpoints", _json_list(listen))
    c.insert_json5("scouting/multicast/enabled", "false")
    return c


def _json_list(items):
    return "[" + ",".join(f'"{e}"' for e in items) + "]"


def _check_endpoint(ep, what):
    if not isinstance(ep, str) or "/" not in ep:
        raise ParameterError(f"{what} must be a Zenoh endpoint like 'tcp/127.0.0.1:7447'",
                             param=what, found=ep)
    return ep


def open_session(router="tcp/127.0.0.1:7447", mode="client"):
    """A Zenoh session connected to ``router`` (a client by default: it
    listens on nothing)."""
    if mode not in ("client", "peer"):
        raise ParameterError("mode must be 'client' or 'peer'", param="mode", found=mode)
    _check_endpoint(router, "router")
    try:
        return _zenoh().open(_config(mode, connect=[router]))
    except Exception as e:  # noqa: BLE001 - zenoh raises its own ZError
        raise ParameterError(f"cannot reach the Zenoh router at {router}: {e}",
                             param="router",
                             hint="start one (zenoh-bridge-ros2dds, rmw_zenohd, or "
                                  "avblocks.interfaces.ros2.open_router()) or give "
                                  "its address") from None


def free_port():
    """A free TCP port on 127.0.0.1 (for tests and examples)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def open_router(endpoint=None):
    """Open a Zenoh router in this process, listening on ``endpoint``
    (default: a free port on 127.0.0.1). Returns ``(session, endpoint)``;
    close the session to stop it. Stands in for ``zenohd`` in tests."""
    if endpoint is None:
        endpoint = f"tcp/127.0.0.1:{free_port()}"
    _check_endpoint(endpoint, "endpoint")
    return _zenoh().open(_config("router", listen=[endpoint])), endpoint


def _mangle(name):
    name = name.strip("/")
    return "%" + name.replace("/", "%") if name else "%"


class Link:
    """One Zenoh session speaking one key convention, with helpers to
    publish and subscribe ROS 2 messages by topic name.

    Parameters
    ----------
    router : str
        Endpoint of the Zenoh router to connect to.
    convention : {"bridge", "rmw_zenoh"}
    domain : int, optional
        ROS domain id (default ``$ROS_DOMAIN_ID`` or 0), rmw_zenoh only.
    node : str
        Node name shown by ``ros2 node list`` (rmw_zenoh only).
    namespace : str
        Node namespace.
    distro : {"jazzy", "humble"}
        Message definitions and type hashes to use.
    mode : {"client", "peer"}
    """

    def __init__(self, router="tcp/127.0.0.1:7447", convention="bridge", *, domain=None,
                 node="avblocks", namespace="/", distro="jazzy", mode="client",
                 session=None):
        if convention not in CONVENTIONS:
            raise ParameterError("unknown key convention", param="transport",
                                 expected=list(CONVENTIONS), found=convention)
        self.convention = convention
        self.distro = distro
        _msgs.typestore(distro)
        if domain is None:
            domain = int(os.environ.get("ROS_DOMAIN_ID", "0") or 0)
        self.domain = int(domain)
        self.node = node
        self.namespace = namespace
        self._own = session is None
        self.session = open_session(router, mode) if session is None else session
        self._tokens = []
        self._subs = []
        self._pubs = []
        self._entity = 0
        self._lock = threading.Lock()
        if convention == "rmw_zenoh":
            self._zid = str(self.session.info.zid())
            self._node_id = 0
            self._token(f"NN/%/{_mangle(namespace)}/{node}", self._node_id)

    # ------------------------------------------------------------ keys
    def key(self, topic, typename):
        """The Zenoh key of ``topic`` carrying ``typename``."""
        t = topic.strip("/")
        if self.convention == "bridge":
            return t
        return f"{self.domain}/{t}/{_msgs.dds_name(typename)}/" \
               f"{_msgs.type_hash(typename, self.distro)}"

    def _token(self, tail, entity):
        key = f"@ros2_lv/{self.domain}/{self._zid}/{self._node_id}/{entity}/{tail}"
        self._tokens.append(self.session.liveliness().declare_token(key))

    def _endpoint_token(self, kind, topic, typename):
        with self._lock:
            self._entity += 1
            ent = self._entity
        self._token(f"{kind}/%/{_mangle(self.namespace)}/{self.node}/{_mangle(topic)}/"
                    f"{_msgs.dds_name(typename)}/{_msgs.type_hash(typename, self.distro)}/"
                    f"{QOS_TOKEN}", ent)

    # ------------------------------------------------------ pub / sub
    def publisher(self, topic, typename):
        """A :class:`Publisher` of ``typename`` on ``topic``."""
        pub = Publisher(self, topic, typename)
        self._pubs.append(pub)
        if self.convention == "rmw_zenoh":
            self._endpoint_token("MP", topic, typename)
        return pub

    def subscribe(self, topic, typename, callback):
        """Call ``callback(payload bytes, receive time)`` (monotonic seconds,
        Zenoh's thread) for every sample on ``topic``."""
        def listener(sample):
            try:
                callback(sample.payload.to_bytes(), time.monotonic())
            except Exception:  # noqa: BLE001 - a callback must not kill Zenoh's thread;
                pass            # callers count and report their own failures
        sub = self.session.declare_subscriber(self.key(topic, typename), listener)
        self._subs.append(sub)
        if self.convention == "rmw_zenoh":
            self._endpoint_token("MS", topic, typename)
        return sub

    def claim(self, keys, timeout=1.0):
        """Declare this session the commander of each key (a liveliness token
        ``avblocks/commander/<key>/<session id>``) and return
        ``{key: [other session ids]}`` of the other sessions holding one.
        The token is declared before asking, so of two sessions starting
        together each sees the other."""
        zid = str(self.session.info.zid())
        for k in keys:
            self._tokens.append(self.session.liveliness().declare_token(
                f"{CLAIM_PREFIX}/{k}/{zid}"))
        others = {}
        for k in keys:
            for reply in self.session.liveliness().get(f"{CLAIM_PREFIX}/{k}/*",
                                                       timeout=timeout):
                if reply.ok is None:
                    continue
                owner = str(reply.ok.key_expr).rsplit("/", 1)[-1]
                if owner != zid:
                    others.setdefault(k, []).append(owner)
        return others

    def close(self):
        """Undeclare everything and close the session (if this link opened it)."""
        for h in self._subs + [p._pub for p in self._pubs] + self._tokens:
            try:
                h.undeclare()
            except Exception:  # noqa: BLE001 - closing anyway
                pass
        self._subs, self._pubs, self._tokens = [], [], []
        if self._own and self.session is not None:
            try:
                self.session.close()
            except Exception:  # noqa: BLE001
                pass
        self.session = None


class Publisher:
    """Puts CDR payloads on one key; adds rmw_zenoh's attachment when the
    link speaks rmw_zenoh."""

    def __init__(self, link, topic, typename):
        self.link = link
        self.topic = topic
        self.key = link.key(topic, typename)
        self._pub = link.session.declare_publisher(self.key)
        self._gid = secrets.token_bytes(16)
        self._seq = 0

    def attachment(self):
        """rmw_zenoh's attachment for the next sample: sequence number (int64),
        source timestamp (int64 ns since the epoch), GID (length byte + 16 bytes)."""
        self._seq += 1
        return (struct.pack("<qq", self._seq, time.time_ns()) + bytes([len(self._gid)])
                + self._gid)

    def put(self, payload):
        if self.link.convention == "rmw_zenoh":
            self._pub.put(payload, attachment=self.attachment())
        else:
            self._pub.put(payload)
