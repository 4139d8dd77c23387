"""A recording recovered, damaged again and recovered again keeps every loss (task rec2, the lead's and new users'
trials): the second recovery wrote only its own losses and the reader reads the newest "pairplay.recovered"
record, so the twice-recovered file of a session that lost a chunk was verified, rebuilt and viewed as whole.
replay/recover.py carries the earlier losses forward; every copy of a recording keeps its metadata; recover's
line says how many messages were lost and where.
"""

import json

import pytest

from pairplay.replay.mcapscan import scan
from pairplay.replay.reader import RECOVERED, read_log, recovered_cut
from pairplay.replay.rebuild import rebuild_recording
from pairplay.replay.recover import recover
from pairplay.services.verify import verify_recording
from pairplay.services.view.sources import recording_items
from pairplay.replay.studydata import recording_damage

from damageutil import small_chunked_session


@pytest.fixture(scope="module")
def whole(tmp_path_factory):
    return small_chunked_session(tmp_path_factory.mktemp("again") / "whole.mcap", "again")


def _chunk_lost(src, dst, which):
    """`src` with chunk `which` (an index of its chunks) overwritten in its middle: its messages are lost."""
    c = scan(src).chunks[which]
    bad = bytearray(src.read_bytes())
    bad[c.offset + c.length // 2:c.offset + c.length // 2 + 16] = b"\xff" * 16
    dst.write_bytes(bytes(bad))
    return dst, f"chunk {c.number} (bytes {c.offset}-{c.offset + c.length})"


def _tail_zeroed(src, dst, n):
    """`src` with its last `n` bytes zeroed (its footer, or its summary too): no message lost."""
    data = src.read_bytes()
    dst.write_bytes(data[:-n] + b"\0" * n)
    return dst


def _said_alike(once, twice):
    """What every verb that reads a recording says of `twice` is what it says of `once`."""
    a, b = read_log(once), read_log(twice)
    assert b.whole and b.lost_at == a.lost_at != [], (a.lost_at, b.lost_at)
    assert b.lost and b.missing and b.source_lost, b.note
    # the same parts named, each with what it lost
    said = a.source_lost.split("): ", 1)[1]
    assert b.source_lost.endswith(said), (a.source_lost, b.source_lost)
    va, vb = verify_recording(once), verify_recording(twice)
    assert (vb.ok, vb.events, vb.not_compared, vb.lost_part) == (va.ok, va.events, va.not_compared, va.lost_part)
    assert not vb.ok and said.split(": its")[0] in vb.error, vb.error
    ra, rb = rebuild_recording(once), rebuild_recording(twice)
    assert rb.lost and rb.damaged_rounds == ra.damaged_rounds != frozenset()
    assert rb.policy == ra.policy
    assert said in recording_damage(b) and recording_damage(b).startswith("damaged: ")
    assert any(note and said in note for _, note in recording_items(twice))


@pytest.mark.parametrize("zeroed", [37, 100])
def test_a_recovered_file_damaged_and_recovered_again_keeps_the_first_losses(whole, tmp_path, zeroed):
    """The lead's trial: a chunk lost, recovered; the recovered file's footer (and summary) zeroed, recovered again.
    The second recovery lost no message itself and wrote "damaged: [summary]", lost_at [], so the twice-recovered
    file was whole to verify (no loss marked: every event after the hole compared), rebuild (not partial), view and
    the report. It now says what the once-recovered file says, and the reader marks the same place."""
    p, part = _chunk_lost(whole, tmp_path / "damaged.mcap", len(scan(whole).chunks) // 2)
    once = recover(p, tmp_path / "once.mcap").output
    again = recover(_tail_zeroed(once, tmp_path / "once-dmg.mcap", zeroed), tmp_path / "twice.mcap")
    _said_alike(once, again.output)
    assert part in read_log(again.output).source_lost
    assert read_log(again.output).source_lost.startswith(
        "recovered from a damaged file (once-dmg.mcap, itself recovered from damaged.mcap): ")
    # one recovery record, holding both recoveries' findings (the old one is not copied: its positions are stale)
    records = [m for m in _metadata(again.output) if m[0] == RECOVERED]
    assert len(records) == 1
    damaged = json.loads(records[0][1]["damaged"])
    assert damaged[0].startswith(part) and damaged[-1].startswith("summary"), damaged
    assert again.lost == [] and part in again.earlier_lost  # (recover's line says them: the test below)
    # a third time: still the same
    thrice = recover(_tail_zeroed(again.output, tmp_path / "twice-dmg.mcap", zeroed), tmp_path / "thrice.mcap")
    _said_alike(once, thrice.output)


def test_a_file_an_older_recover_made_twice_is_read_with_every_recovery_s_losses(whole, tmp_path):
    """A file an older pairplay recovered twice holds the first recovery's record, copied, and the second's after
    it, which said only its own findings (a summary: no message lost); the reader read the newest alone, so the
    session was whole to every verb. It folds them (reader.folded_recovery): the same as the once-recovered file."""
    from pairplay.replay.reader import LOST_AT_KEY
    from pairplay.replay.writer import EventLogWriter

    p, part = _chunk_lost(whole, tmp_path / "damaged.mcap", len(scan(whole).chunks) // 2)
    once = recover(p, tmp_path / "once.mcap").output
    old = tmp_path / "old-twice.mcap"
    w = EventLogWriter(old)
    for name, data in _metadata(once):
        w.add_metadata(name, data)
    for r in read_log(once).events:
        w.write(r.key, r.payload, log_time_ns=r.log_time_ns, sequence=r.event.seq)
    w.add_metadata(RECOVERED, {"source": str(tmp_path / "once-dmg.mcap"), "truncated": "false",
                               "data_complete": "true", "reason": "summary: unreadable at byte 1",
                               "damaged": json.dumps(["summary: unreadable at byte 1"]), LOST_AT_KEY: "[]",
                               "lost": "[]"})
    w.close()
    _said_alike(once, old)


def test_a_second_recovery_that_loses_more_moves_the_earlier_marks_to_where_they_fall(whole, tmp_path, monkeypatch):
    """The second damage loses a chunk before the first's hole: the earlier mark, a count of messages of the
    once-recovered file, is moved back by what was lost before it, so each mark still stands before the same
    event; both parts are named."""
    import pairplay.replay.recover as rec

    monkeypatch.setattr(rec, "CHUNK_SIZE", 4096)  # a recovered file of many chunks, so one can be lost
    chunks = scan(whole).chunks
    p, first = _chunk_lost(whole, tmp_path / "damaged.mcap", len(chunks) * 2 // 3)
    once = recover(p, tmp_path / "once.mcap").output
    a = read_log(once)
    [mark] = a.lost_at
    after_hole = a.events[mark].payload  # the first event after the first loss
    assert len(scan(once).chunks) > 4
    p2, second = _chunk_lost(once, tmp_path / "once-dmg.mcap", 1)
    n = sum(c.listed for c in scan(p2).chunks if not c.intact)  # what the second damage lost
    twice = recover(p2, tmp_path / "twice.mcap")
    b = read_log(twice.output)
    assert n > 0 and len(b.events) == len(a.events) - n
    assert len(b.lost_at) == 2 and b.events[b.lost_at[1]].payload == after_hole, (a.lost_at, b.lost_at)
    assert b.lost_at[1] == mark - n
    assert read_log(p2).lost_at == b.lost_at  # and the damaged copy read as it is marks the same places
    assert first in b.source_lost and second in b.source_lost, b.source_lost
    v = verify_recording(twice.output)
    assert not v.ok and v.lost_part and v.events == b.lost_at[0] and first in v.error and second in v.error
    assert twice.lost == [f"{second}: its {n} messages"] and twice.lost_messages == n


def test_a_recovered_cut_recovered_again_is_still_cut(whole, tmp_path):
    """A file cut before its Data End, recovered (its tail is lost), its copy's footer zeroed and recovered again:
    the second recovery's source was not cut, and its record said so alone: verify no longer excused the tail and
    rebuild called the session whole."""
    data = whole.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[:len(data) // 3])
    once = recover(cut, tmp_path / "once.mcap").output
    assert recovered_cut(read_log(once).metadata[RECOVERED])
    twice = recover(_tail_zeroed(once, tmp_path / "once-dmg.mcap", 37), tmp_path / "twice.mcap").output
    assert recovered_cut(read_log(twice).metadata[RECOVERED])
    va, vb = verify_recording(once), verify_recording(twice)
    assert vb.truncated and vb.events == va.events and vb.verdict.split("(")[0] == va.verdict.split("(")[0]
    assert rebuild_recording(twice).partial and "recovered from a cut file" in rebuild_recording(twice).partial


def test_recover_says_how_many_messages_were_lost_and_where(whole, tmp_path, capsys):
    """Recover's line named each damaged part's check ("its records are not read") but not what was lost: the
    count the lost chunk's Message Indexes give, with its noun, and the part; a damage that lost no message says
    so; a recovered file recovered again says the earlier losses it carries over."""
    from pairplay.cli.main import main

    p, part = _chunk_lost(whole, tmp_path / "damaged.mcap", len(scan(whole).chunks) // 2)
    listed = next(c.listed for c in scan(p).chunks if not c.intact)
    assert listed > 1
    assert main(["recover", str(p), "-o", str(tmp_path / "once.mcap")]) == 0
    [line] = capsys.readouterr().out.splitlines()
    assert f"; {listed} messages lost ({part}: its {listed} messages); every intact part kept; " in line, line
    _tail_zeroed(tmp_path / "once.mcap", tmp_path / "once-dmg.mcap", 37)
    assert main(["recover", str(tmp_path / "once-dmg.mcap"), "-o", str(tmp_path / "twice.mcap")]) == 0
    [line] = capsys.readouterr().out.splitlines()
    assert "; no message lost; every intact part kept; " in line, line
    assert (f"; what its source had lost is carried over (recovered from a damaged file (damaged.mcap): {part}: "
            f"its {listed} messages lost)") in line, line


def test_recover_counts_what_unreadable_bytes_lost_by_the_summary_or_says_it_is_not_known(whole, tmp_path, capsys):
    """A chunk whose record head is zeroed: its bytes do not read, so no Message Index says what they held; the
    summary's Statistics (its CRC holds) count the file's messages, and the difference is what was lost. With the
    summary zeroed too, nothing says: the line says the count is not known, never a number it cannot know."""
    from pairplay.cli.main import main

    c = scan(whole).chunks[5]
    data = bytearray(whole.read_bytes())
    data[c.offset:c.offset + 9] = b"\0" * 9
    p = tmp_path / "head.mcap"
    p.write_bytes(bytes(data))
    n = len(read_log(whole).events) - len(read_log(p).events)
    assert main(["recover", str(p), "-o", str(tmp_path / "r.mcap")]) == 0
    [line] = capsys.readouterr().out.splitlines()
    # (the summary's Chunk Index names the bytes as chunk 5, and its Message Indexes after it count its messages:
    # mcapscan `headless_chunks`; the same count as the Statistics give)
    assert f"; {n} messages lost (chunk 5 (bytes {c.offset}-" in line and f": its {n} messages); every intact part kept" in line
    _tail_zeroed(p, tmp_path / "head-and-tail.mcap", 37)
    assert main(["recover", str(tmp_path / "head-and-tail.mcap"), "-o", str(tmp_path / "r2.mcap")]) == 0
    [line] = capsys.readouterr().out.splitlines()
    assert f"; messages lost, how many is not known (bytes {c.offset}-" in line, line


def test_the_soak_s_altered_copy_keeps_the_recording_s_metadata(whole, tmp_path):
    """tools/verify_soak.py copies a recording's messages into a new MCAP with one event altered: it dropped every
    metadata record, so a copy of a recovered file lost what its source had lost (the one other writer that
    copies a recording's messages: recover carries them, participant export zips the bytes)."""
    import importlib.util
    from pathlib import Path

    spec = importlib.util.spec_from_file_location("verify_soak", Path(__file__).parents[1] / "tools" / "verify_soak.py")
    soak = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(soak)
    p, part = _chunk_lost(whole, tmp_path / "damaged.mcap", len(scan(whole).chunks) // 2)
    once = recover(p, tmp_path / "once.mcap").output
    soak.alter_one_suggestion(once, tmp_path / "altered.mcap")
    assert part in read_log(tmp_path / "altered.mcap").source_lost
    assert _metadata(tmp_path / "altered.mcap") == _metadata(once)


def _metadata(path):
    from mcap.records import Metadata
    return [(r.name, dict(r.metadata)) for r in scan(path).records if isinstance(r, Metadata)]
