"""A recovered copy holds pairplay's schemas alone: a schema that is not pairplay's is left out, and said.

Rule (replay/recover.py `_PairplaySchemas`): each event channel of the copy has pairplay's schema of its event (the
source's when it is that, else pairplay's own), any other channel none; every Schema record of the source that is
not pairplay's (one in place of an event's, one no channel uses, one of a channel that is no pairplay event) is
left out, counted in recover's line and in the copy's "pairplay.recovered" record. Before, recover copied every
Schema record along: the copy misdescribed its events to every other MCAP reader, unsaid (the readers say it of
the source: reader.EventLog.foreign_schemas). Real parts: a frozen sample written again with the mcap library's
Writer, with foreign schemas, then cut; the `pairplay recover` verb.
"""

from __future__ import annotations

from mcap.reader import make_reader
from mcap.writer import Writer

from pairplay.cli.main import main
from pairplay.replay.reader import RECOVERED, not_pairplays, read_any_log

from rewrite_mcap import SAMPLE


def _hostile(dst):
    """SAMPLE written again, its RoundStarted channel's schema `{"type":"string"}`, plus a schema no channel uses
    and a channel that is no pairplay event with a schema of its own and one message; cut at two thirds."""
    with open(SAMPLE, "rb") as f, open(dst, "wb") as out:
        reader = make_reader(f)
        w = Writer(out, chunk_size=4096)
        w.start(profile="", library="pairplay tests (hostile schemas)")
        w.register_schema("orphan", "jsonschema", b'{"title":"orphan"}')
        notes = w.register_channel("notes", "json", w.register_schema("note", "jsonschema", b'{"type":"object"}'))
        w.add_message(notes, 1, b'{"note":"hand-made"}', 1)
        schemas, channels = {}, {}
        for s, c, m in reader.iter_messages(log_time_order=False):
            if c.id not in channels:
                data = b'{"type":"string"}' if c.topic.endswith("/RoundStarted") else s.data
                schemas[c.id] = w.register_schema(s.name, s.encoding, data)
                channels[c.id] = w.register_channel(c.topic, c.message_encoding, schemas[c.id], dict(c.metadata))
            w.add_message(channels[c.id], m.log_time, m.data, m.publish_time, m.sequence)
        for r in reader.iter_metadata():
            w.add_metadata(r.name, dict(r.metadata))
        w.finish()
    data = dst.read_bytes()
    dst.write_bytes(data[:len(data) * 2 // 3])
    return dst


def test_recover_leaves_out_the_schemas_that_are_not_pairplays_and_says_so(tmp_path, capsys):
    src = _hostile(tmp_path / "hostile.mcap")
    assert "RoundStarted: not the JSON Schema of its event" in read_any_log(src).foreign_schemas
    out = tmp_path / "rec.mcap"
    assert main(["recover", str(src), "-o", str(out)]) == 0
    line = capsys.readouterr().out
    assert "3 schemas not pairplay's left out ('orphan', ...): the events' channels have pairplay's" in line, line
    with open(out, "rb") as f:
        summary = make_reader(f).get_summary()
    for channel in summary.channels.values():
        tag = channel.topic.rsplit("/", 1)[-1]
        if channel.topic == "notes":
            assert channel.schema_id == 0
            continue
        s = summary.schemas[channel.schema_id]
        assert not not_pairplays(tag, (s.name, s.encoding, s.data)), (tag, s)
    assert {s.name for s in summary.schemas.values()} <= {c.topic.rsplit("/", 1)[-1] for c in summary.channels.values()}
    log = read_any_log(out)
    assert not log.foreign_schemas and log.of("RoundStarted")
    assert log.metadata[RECOVERED]["schemas_left_out"].startswith("3 schemas not pairplay's left out")
