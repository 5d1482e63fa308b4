"""Recordings rewritten for tests: a real recording with one thing changed."""

import json

import numpy as np
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from hapticop.recording import arrays


def rewrite_recording(source, target, *, sample=None, parameters=None, without_topic=None, attachments=True,
                      replaced=None):
    """A copy of a recording with one stream sample changed (`sample`: (topic, number, fn of the
    array)), the parameters changed (`parameters`: fn of the dict), a channel left out, nothing attached,
    or some attachments' bytes `replaced` (name: bytes)."""
    with open(source, "rb") as stream, open(target, "wb") as out:
        reader = make_reader(stream)
        summary = reader.get_summary()
        writer = Writer(out, compression=CompressionType.ZSTD)
        writer.start(profile="", library="test")
        schemas = {sid: writer.register_schema(s.name, s.encoding, s.data) for sid, s in summary.schemas.items()}
        channels = {cid: writer.register_channel(c.topic, c.message_encoding, schemas.get(c.schema_id, 0),
                                                 dict(c.metadata))
                    for cid, c in summary.channels.items() if c.topic != without_topic}
        for _, channel, message in reader.iter_messages(log_time_order=False):
            if channel.id not in channels:
                continue
            data = message.data
            if sample is not None and channel.topic == sample[0] and message.sequence == sample[1]:
                meta = channel.metadata
                value = arrays.decode(data, meta["dtype"], tuple(json.loads(meta["shape"]))).copy()
                sample[2](value)
                raw = value.astype(np.dtype(meta["dtype"]).newbyteorder("<")).tobytes()
                data = arrays.prefix(len(raw)) + raw
            writer.add_message(channels[channel.id], message.log_time, data, message.publish_time, message.sequence)
        for record in reader.iter_attachments():
            if not attachments:
                continue
            data = (replaced or {}).get(record.name, record.data)
            if parameters is not None and record.name == "parameters.json":
                changed = json.loads(data)
                parameters(changed)
                data = json.dumps(changed).encode()
            writer.add_attachment(record.create_time, record.log_time, record.name, record.media_type, data)
        for record in reader.iter_metadata():
            writer.add_metadata(record.name, dict(record.metadata))
        writer.finish()
    return target
