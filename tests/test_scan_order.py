"""mcapscan's order checks inside and across chunks, and its Message Index check, on real MCAP files (mcap's own
Writer): the scan notes a chunk's sequence numbers and log-time order as it opens the chunk and checks each
channel's Message Index against the chunk's messages in file order, falling back to the message-by-message
checks (and the order-blind comparison of index and chunk) only where they disagree (issue 16, rebuild's
speed). These pin that nothing the fallbacks find was lost: each finding's words, and that an index listing
the right messages in another order is no damage."""

import struct

from mcap.writer import CompressionType, Writer

from pairplay.replay.mcapscan import scan
from pairplay.replay.reader import read_any_log

TOPIC = "pairplay/s1/participant/CardPicked"


def written(path, messages, chunk_size=1 << 20, metadata=()):
    """`messages` as (channel 0 or 1, log time, sequence) written at `path` by mcap's Writer, uncompressed (its
    bytes are then found and changed as they are), in one chunk, or one chunk per message (`chunk_size` 1)."""
    with open(path, "wb") as f:
        w = Writer(f, chunk_size=chunk_size, compression=CompressionType.NONE)
        w.start()
        schema = w.register_schema("raw", "jsonschema", b"{}")
        channels = [w.register_channel(TOPIC, "json", schema), w.register_channel(TOPIC + "2", "json", schema)]
        for name, values in metadata[:1]:
            w.add_metadata(name, values)
        for ch, t, seq in messages:
            w.add_message(channels[ch], t, b'{"type":"CardPicked"}', t, sequence=seq)
        for name, values in metadata[1:]:
            w.add_metadata(name, values)
        w.finish()
    return path


def findings(path):
    return [str(d) for d in scan(path).damage]


def test_a_sequence_going_back_inside_a_chunk_is_named(tmp_path):
    p = written(tmp_path / "a.mcap", [(0, 10, 1), (0, 11, 2), (1, 12, 5), (0, 13, 2), (0, 14, 3)])
    [finding] = findings(p)
    assert finding.startswith("chunk 0 (bytes ") and finding.endswith(
        "channel 1's sequence goes back from 2 (chunk 0) to 2: records out of order"), finding


def test_a_sequence_going_back_from_one_chunk_to_the_next_is_named(tmp_path):
    p = written(tmp_path / "a.mcap", [(0, 10, 1), (1, 11, 1), (0, 12, 3), (1, 13, 2), (0, 14, 2)], chunk_size=1)
    assert len(scan(p).chunks) == 5
    [finding] = findings(p)
    assert finding.startswith("chunk 4 (bytes ") and finding.endswith(
        "channel 1's sequence goes back from 3 (chunk 2) to 2: records out of order"), finding


def test_sequences_that_rise_per_channel_and_zeros_are_no_finding(tmp_path):
    """Each channel's numbers rise on their own, interleaved; 0 is "no sequence" (never compared)."""
    p = written(tmp_path / "a.mcap", [(0, 10, 5), (1, 11, 1), (0, 12, 0), (0, 13, 6), (1, 14, 2), (1, 15, 0)])
    q = written(tmp_path / "b.mcap", [(0, 10, 5), (1, 11, 1), (0, 12, 0), (0, 13, 6), (1, 14, 2), (1, 15, 0)],
                chunk_size=1)
    assert scan(p).whole and scan(q).whole


def test_log_times_going_back_inside_a_chunk_are_named_at_that_channels_index(tmp_path):
    p = written(tmp_path / "a.mcap", [(0, 10, 1), (0, 25, 2), (1, 30, 1), (0, 20, 3), (1, 40, 2)])
    [finding] = findings(p)
    assert finding.startswith("message index of chunk 0 (byte ") and finding.endswith(": log times not in order")
    # the other channel's times went forward: its index is no finding, though the chunk's times went back
    assert len(read_any_log(p).bad) == 5  # every message was read (none a pairplay event)


def _first_index(path):
    """(offset, channel, entries) of the first Message Index record after the file's only chunk."""
    [c] = scan(path).chunks
    data = path.read_bytes()
    at = c.offset + c.length
    opcode, length, channel, size = struct.unpack_from("<BQHI", data, at)
    assert opcode == 0x07
    flat = struct.unpack_from(f"<{size // 8}Q", data, at + 15)
    return at + 15, channel, list(zip(flat[::2], flat[1::2]))


def _rewrite_index(path, entries):
    at, _, _ = _first_index(path)
    data = bytearray(path.read_bytes())
    data[at:at + 16 * len(entries)] = struct.pack(f"<{2 * len(entries)}Q", *(x for e in entries for x in e))
    path.write_bytes(bytes(data))


def test_an_index_listing_the_chunks_messages_in_another_order_is_no_damage(tmp_path):
    """The specification does not order a Message Index's entries by offset: the same entries in another
    order (two messages of one log time, swapped) are the chunk's messages, not damage."""
    p = written(tmp_path / "a.mcap", [(0, 10, 1), (0, 10, 2), (0, 11, 3), (1, 12, 1)])
    _, _, entries = _first_index(p)
    assert [t for t, _ in entries] == [10, 10, 11]
    _rewrite_index(p, [entries[1], entries[0], entries[2]])
    assert _first_index(p)[2] != entries
    assert scan(p).whole and len(read_any_log(p).bad) == 4


def test_an_index_entry_that_points_at_no_message_is_named(tmp_path):
    p = written(tmp_path / "a.mcap", [(0, 10, 1), (0, 11, 2), (0, 12, 3), (1, 12, 1)])
    _, channel, entries = _first_index(p)
    _rewrite_index(p, [entries[0], (entries[1][0], entries[1][1] + 1), entries[2]])
    [finding] = findings(p)
    assert finding.startswith("message index of chunk 0 (byte ") and finding.endswith(
        f"lists 3 messages of channel {channel}, the chunk holds 3 (1 entry point at no such message)"), finding


def test_an_index_entry_with_another_log_time_is_named(tmp_path):
    """Same offsets, a time changed (still in order): not the chunk's messages."""
    p = written(tmp_path / "a.mcap", [(0, 10, 1), (0, 12, 2), (0, 14, 3)])
    _, channel, entries = _first_index(p)
    _rewrite_index(p, [entries[0], (11, entries[1][1]), entries[2]])
    [finding] = findings(p)
    assert finding.endswith(f"lists 3 messages of channel {channel}, the chunk holds 3 (1 entry point at no such "
                            "message)"), finding


def test_the_scan_keeps_the_data_sections_metadata_records_apart_in_file_order(tmp_path):
    """`Scan.metadata_records`: what the reader reads a recovered file's losses from (no pass over every
    record to find them), the same records, in the same order, as among `records`."""
    p = written(tmp_path / "a.mcap", [(0, 10, 1), (1, 11, 1)], chunk_size=1,
                metadata=[("first", {"a": "1"}), ("second", {"b": "2"}), ("third", {"c": "3"})])
    s = scan(p)
    among = [r for r in s.records if type(r).__name__ == "Metadata"]
    assert [m.name for m in s.metadata_records] == ["first", "second", "third"]
    assert s.metadata_records == among and all(a is b for a, b in zip(s.metadata_records, among))
    assert read_any_log(p).metadata == {"first": {"a": "1"}, "second": {"b": "2"}, "third": {"c": "3"}}
