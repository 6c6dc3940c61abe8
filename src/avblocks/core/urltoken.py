"""The token in the URL path of the local servers (the live view, the
editor): ``http://127.0.0.1:PORT/<token>/...``. One implementation of the
two checks every server makes: a token is URL-safe (:func:`make_token`),
and a request path is under it (:func:`under_token`, compared in constant
time)."""

from __future__ import annotations

import hmac
import secrets

from .errors import AvError


def make_token(token=None, error=AvError) -> str:
    """``token``, or a new random one (24 bytes, URL-safe base64); raises
    ``error`` (an :class:`AvError` class) when a given token is not made of
    letters, digits, ``-`` and ``_``."""
    token = token or secrets.token_urlsafe(24)
    if not isinstance(token, str) or not token.replace("-", "").replace("_", "").isalnum():
        raise error("token must be URL-safe (letters, digits, - and _)",
                    found=repr(token)[:40])
    return token


def under_token(path, token):
    """The rest of ``path`` (``str`` or ``bytes``, query string removed)
    after its first segment when that segment is ``token``: ``""`` for
    ``/<token>`` itself, ``"/..."`` below it; None when the first segment is
    not the token (compared in constant time)."""
    raw = path.encode() if isinstance(path, str) else bytes(path)
    prefix = b"/" + token.encode()
    head, after = raw[: len(prefix)], raw[len(prefix):]
    if not hmac.compare_digest(head, prefix) or not (after == b"" or after.startswith(b"/")):
        return None
    return after.decode() if isinstance(path, str) else after
