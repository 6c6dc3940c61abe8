"""Reading MCAP files back independently of the writer: the ``mcap``
package's reader, protobuf messages decoded from the FileDescriptorSets
embedded in the file (``mcap-protobuf-support``, Google's protobuf
runtime), JSON messages checked against the JSON schemas embedded in the
file (``jsonschema``). Nothing of avblocks is used."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass

import pytest


def need_readers():
    try:
        import jsonschema  # noqa: F401
        import mcap  # noqa: F401
        import mcap_protobuf  # noqa: F401
    except ImportError as e:
        if os.environ.get("CI"):
            raise
        pytest.skip(f"MCAP readers not installed: {e}")


@dataclass
class Msg:
    topic: str
    schema: str
    encoding: str
    log_time: int
    publish_time: int
    value: object


def read(path):
    """``(messages by topic, summary, metadata)`` of an MCAP file."""
    import jsonschema
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory
    out = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        for schema, channel, message in reader.iter_messages():
            if schema.encoding == "protobuf":
                continue
            assert schema.encoding == "jsonschema" and channel.message_encoding == "json"
            value = json.loads(message.data)
            jsonschema.validate(value, json.loads(schema.data))
            out.setdefault(channel.topic, []).append(Msg(
                channel.topic, schema.name, schema.encoding, message.log_time,
                message.publish_time, value))
    proto = [c.topic for c in summary.channels.values()
             if summary.schemas[c.schema_id].encoding == "protobuf"]
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, decoded in reader.iter_decoded_messages(topics=proto):
            out.setdefault(channel.topic, []).append(Msg(
                channel.topic, schema.name, schema.encoding, message.log_time,
                message.publish_time, decoded))
    return out, summary, metadata


def stamp_ns(ts):
    """Nanoseconds of a decoded google.protobuf.Timestamp."""
    return ts.seconds * 10**9 + ts.nanos
