"""A real recording written again with the mcap library's own Writer, changed on the way as a hostile hand or a
broken copying tool would change it (tests of what every verb reading a recording says of such a file:
replay/reader.py). What may change: each message (`each`: its copies, or none), each channel's topic (`topic`),
each schema's bytes (`schema`), the MCAP sequence numbers (`renumber`: 1, 2, 3, ... over the file, so the copies
pass every check of the MCAP format); `chunk_size` as the Writer's."""

from __future__ import annotations

from pathlib import Path

from mcap.reader import make_reader
from mcap.writer import Writer

SAMPLE = Path(__file__).resolve().parents[1] / "recordings" / "samples" / "sim-ashley-fmt2.mcap"


def rewritten(dst, src=SAMPLE, each=lambda channel, message: [message], topic=lambda t: t,
              schema=lambda data: data, renumber: bool = False, chunk_size: int = 1024 * 1024,
              repeat_channels: bool = False):
    """`src` written again to `dst` (see the module rule); `dst`. `repeat_channels`: every channel's record again at
    the start of each chunk, as MCAP lets a writer do (so a chunk is read on its own: the Go `mcap` tool's
    files); the library's Writer writes each once, so its chunk builder is given them here."""
    with open(src, "rb") as f, open(dst, "wb") as out:
        reader = make_reader(f)
        w = Writer(out, chunk_size=chunk_size)
        w.start(profile="", library="pairplay tests (rewrite_mcap)")
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        n = 0
        for s, c, m in reader.iter_messages(log_time_order=False):
            if s is not None and s.id not in schemas:
                schemas[s.id] = w.register_schema(s.name, s.encoding, schema(s.data))
            if c.id not in channels:
                channels[c.id] = w.register_channel(topic(c.topic), c.message_encoding, schemas.get(c.schema_id, 0),
                                                    dict(c.metadata))
            for copy in each(c, m):
                builder = w._Writer__chunk_builder  # (the Writer's own, name-mangled: no public way to repeat)
                if repeat_channels and builder.num_messages == 0:
                    for record in w._Writer__channels.values():
                        builder.add_channel(record)
                n += 1
                w.add_message(channels[c.id], copy.log_time, copy.data, copy.publish_time,
                              n if renumber else copy.sequence)
        for name, meta in ((r.name, r.metadata) for r in reader.iter_metadata()):
            w.add_metadata(name, dict(meta))
        w.finish()
    return Path(dst)


def another_session(dst, k: int = 1, src=SAMPLE):
    """`src` written again as another session (`k` ns later a start, the same events otherwise): what a batch
    needs of several recordings, each a session of its own (replay/onesession.py: a copy of one file is the same
    session, refused twice in one batch); `dst`."""
    import dataclasses
    import json

    def each(channel, message):
        if not channel.topic.endswith("/SessionStarted"):
            return [message]
        event = json.loads(message.data)
        t = event["time_ns"]
        event["time_ns"] = t + k if isinstance(t, int) else {**t, "nsec": (t["nsec"] + k) % 1_000_000_000}
        return [dataclasses.replace(message, data=json.dumps(event, separators=(",", ":")).encode())]
    return rewritten(dst, src, each=each)
