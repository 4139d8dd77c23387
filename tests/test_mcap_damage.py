"""Damaged, cut and reordered recordings, made from a real one by what the MCAP specification lets a reader check
(issue 10, item 10; mcap.dev/spec: magic, record opcode + uint64 length, Chunk with uncompressed size and CRC-32,
Message Index records after each chunk, Data End with the data-section CRC, summary with Chunk Indexes and
Statistics, Footer with the summary CRC, closing magic).

Every reader path (read_log behind rebuild, replay, verify and view; recover) must say the file is not whole and
which part is affected, never return an event that was not in the file, and keep every intact part.
"""

import json
import struct

import pytest

from pairplay.errors import InputError
from pairplay.replay.check import MCAP_MAGIC

from pairplay.replay.mcapscan import scan
from pairplay.replay.reader import read_any_log, read_log
from pairplay.replay.rebuild import rebuild_recording
from pairplay.replay.recover import recover
from pairplay.replay.writer import EventLogWriter
from pairplay.services.verify import verify_recording
from pairplay.services.view.sources import recording_items

from damageutil import small_chunked_session


@pytest.fixture(scope="module")
def whole(tmp_path_factory):
    """A real recording of a 3-round session, written by the recorder's writer in small chunks (about 20)."""
    return small_chunked_session(tmp_path_factory.mktemp("dmg") / "whole.mcap", "dmg")


def payloads(path):
    return [r.payload for r in read_log(path).events]


def variant(tmp_path, data, name="damaged.mcap"):
    p = tmp_path / name
    p.write_bytes(data)
    return p


def test_the_whole_recording_checks_out(whole):
    s = scan(whole)
    assert s.whole and s.summary and len(s.chunks) >= 8 and all(c.intact for c in s.chunks)
    assert read_log(whole).whole and verify_recording(whole).ok


def test_a_cut_at_any_offset_keeps_exactly_the_chunks_before_it(tmp_path):
    # a recording of one round, not the module's three: each of the ~180 cuts reads, recovers and scans the file
    # (~7 s of CPU for the 78 KB of three rounds); one round's chunks are as many kinds of place to cut (magic,
    # header, chunk heads and data, message indexes, summary, footer), each sampled more densely
    whole = small_chunked_session(tmp_path / "whole.mcap", "cut", rounds=1)
    data = whole.read_bytes()
    full = payloads(whole)
    chunks = scan(whole).chunks
    assert len(chunks) >= 8  # cuts between many chunks, wholly before and after
    per_chunk = [len(c.messages) for c in chunks]
    offsets = sorted(set(range(0, len(data), max(1, len(data) // 150))) | {c.offset for c in chunks}
                     | {c.offset + c.length for c in chunks} | {len(data) - 1, len(data) - 8, len(data) - 9, 5, 8, 9})
    for cut in offsets:
        p = variant(tmp_path, data[:cut])
        log = read_any_log(p)  # (read_log refuses a file cut inside MCAP's magic: no recording at all, below)
        assert not log.whole and log.truncated and log.error, cut
        kept = sum(n for c, n in zip(chunks, per_chunk) if c.offset + c.length <= cut)
        got = [r.payload for r in log.events]
        assert got == full[:len(got)], cut  # nothing invented, nothing reordered
        assert len(got) == kept, cut  # every chunk wholly before the cut is read
        if cut < len(MCAP_MAGIC):  # not even the magic: not a recording, and recover says so (issue 10, item 4)
            with pytest.raises(InputError):
                recover(p, tmp_path / "out.mcap")
            with pytest.raises(InputError):  # as the public reader does
                read_log(p)
            continue
        assert read_log(p).events == log.events, cut
        if not any(type(r.event).__name__ == "SessionStarted" for r in log.events):  # cut before the session's start
            with pytest.raises(InputError, match="holds no session"):  # was: exit 0, an empty file written
                recover(p, tmp_path / "out.mcap")
            assert not (tmp_path / "out.mcap").exists()
            continue
        done = recover(p, tmp_path / "out.mcap")
        assert done.messages == kept and done.truncated and scan(done.output).whole
        (tmp_path / "out.mcap").unlink()


@pytest.mark.parametrize("where", ["data", "start", "end"])
def test_a_flipped_byte_in_a_chunk_loses_that_chunk_only_and_is_named(whole, tmp_path, where):
    data = whole.read_bytes()
    full = payloads(whole)
    chunks = scan(whole).chunks
    for k in (0, len(chunks) // 2, len(chunks) - 1):
        c = chunks[k]
        at = {"data": c.offset + c.length - 7, "start": c.offset + 9, "end": c.offset + 17}[where]
        bad = bytearray(data)
        bad[at] ^= 0x5A
        p = variant(tmp_path, bytes(bad))
        log = read_log(p)
        assert not log.whole and log.damage, (k, where)
        assert any(f"chunk {k} " in str(d) or "data section" in str(d) for d in log.damage), log.error
        got = [r.payload for r in log.events]
        assert set(got) <= set(full)
        if where == "data":  # the chunk's CRC fails: only its messages are lost, every other chunk is read
            assert len(got) == len(full) - len(c.messages)
            assert f"chunk {k} (bytes {c.offset}-{c.offset + c.length}): CRC mismatch" in log.error or \
                   "does not decompress" in log.error
        v = verify_recording(p)
        assert not v.ok and v.verdict.startswith("verify: FAIL: the file is damaged (")
        if log.no_session:  # the chunk of its SessionStarted lost: refused, as every verb refuses it
            with pytest.raises(InputError, match="holds no session: .* no SessionStarted in its intact parts: the file "
                                                 "is damaged"):
                recover(p, tmp_path / "out.mcap")
            assert not (tmp_path / "out.mcap").exists()
            continue
        done = recover(p, tmp_path / "out.mcap")
        assert done.messages == len(got) and done.damaged
        rv = verify_recording(done.output)
        if len(got) < len(full):
            assert not rv.ok and "recovered from a damaged file" in rv.error
        else:  # a chunk's header damaged, every message read: its copy holds the whole session (it FAILed)
            assert rv.ok and "recovered from a damaged file; no message was lost" in rv.reach, rv.error
        (tmp_path / "out.mcap").unlink()


def test_a_damaged_record_length_is_skipped_and_the_chunks_after_it_are_read(whole, tmp_path):
    data = whole.read_bytes()
    chunks = scan(whole).chunks
    c = chunks[3]
    bad = bytearray(data)
    bad[c.offset + 1:c.offset + 9] = struct.pack("<Q", 2**40)  # chunk 3's length now runs past the end
    log = read_log(variant(tmp_path, bytes(bad)))
    assert not log.whole and any(f"bytes {c.offset}-" in str(d) for d in log.damage)
    assert len(log.events) == sum(len(x.messages) for x in chunks) - len(c.messages)


def test_swapped_chunks_are_reported_out_of_order(whole, tmp_path):
    data = whole.read_bytes()
    chunks = scan(whole).chunks
    a, b = chunks[2], chunks[3]
    # each chunk with the Message Index records that follow it, up to the next chunk
    block_a, block_b = data[a.offset:b.offset], data[b.offset:chunks[4].offset]
    swapped = data[:a.offset] + block_b + block_a + data[chunks[4].offset:]
    for p in (variant(tmp_path, swapped), variant(tmp_path, swapped[:chunks[-1].offset + chunks[-1].length], "cut.mcap")):
        log = read_log(p)
        assert not log.whole and "out of order" in log.error, log.error
        assert not verify_recording(p).ok


def test_footer_summary_and_index_damage_is_found(whole, tmp_path):
    data = whole.read_bytes()
    footer_at = len(data) - 8 - 29
    summary_start = struct.unpack_from("<Q", data, footer_at + 9)[0]
    no_footer = variant(tmp_path, data[:footer_at], "nofooter.mcap")
    assert "footer" in read_log(no_footer).error and read_log(no_footer).truncated
    bad = bytearray(data)
    bad[summary_start + 20] ^= 1
    log = read_log(variant(tmp_path, bytes(bad), "summary.mcap"))
    assert any(d.part.startswith("summary") or d.part.startswith("chunk index") for d in log.damage), log.error
    no_magic = variant(tmp_path, data[:-8] + b"\x00" * 8, "magic.mcap")
    assert "magic" in read_log(no_magic).error
    head = bytearray(data)
    head[0] = 0
    log = read_any_log(variant(tmp_path, bytes(head), "head.mcap"))  # (no MCAP magic: read_log refuses it, as verbs do)
    assert "header" in log.error and len(log.events) == len(payloads(whole))  # every chunk still read
    # a Message Index that points at the wrong offset
    chunks = scan(whole).chunks
    c = chunks[1]
    idx = c.offset + c.length  # the first Message Index after chunk 1
    assert data[idx] == 0x07
    mi = bytearray(data)
    mi[idx + 9 + 2 + 4 + 8] ^= 0x10  # the first entry's offset
    log = read_log(variant(tmp_path, bytes(mi), "index.mcap"))
    assert any("message index of chunk 1" in str(d) for d in log.damage), log.error


def test_every_reader_path_says_which_part(whole, tmp_path):
    data = whole.read_bytes()
    c = scan(whole).chunks[2]
    bad = bytearray(data)
    bad[c.offset + c.length - 3] ^= 0xFF
    p = variant(tmp_path, bytes(bad))
    part = f"chunk 2 (bytes {c.offset}-{c.offset + c.length})"
    assert part in rebuild_recording(p).note
    assert part in verify_recording(p).verdict
    notes = [note for _, note in recording_items(p) if note]
    assert any(part in n for n in notes)
    done = recover(p, tmp_path / "r.mcap")
    meta = read_log(done.output).metadata["pairplay.recovered"]
    assert any(part in d for d in json.loads(meta["damaged"])) and meta["lost_chunks"] == "1"


def test_random_damage_never_raises_and_never_invents(whole, tmp_path):
    import random

    data = whole.read_bytes()
    full = set(payloads(whole))
    rng = random.Random(7)
    for _ in range(40):
        bad = bytearray(data)
        for _ in range(rng.randint(1, 4)):
            bad[rng.randrange(len(bad))] = rng.randrange(256)
        log = read_log(variant(tmp_path, bytes(bad)))
        assert {r.payload for r in log.events} <= full
        if bytes(bad) != data:
            assert not log.whole or log.events == read_log(whole).events


def test_a_damaged_file_with_no_round_left_whole_is_called_damaged_not_cut(whole, tmp_path, capsys):
    """A whole file whose chunks fail their CRC: rebuild said "the file is cut before round 1"; it names the
    damage, in the words replay --verify uses (reader.EventLog.brief: short, what was lost where)."""
    from pairplay.cli.main import main

    bad = bytearray(whole.read_bytes())
    for c in scan(whole).chunks[1:]:  # the session's start (chunk 0) stays; every round's end is damaged
        bad[c.offset + c.length - 7] ^= 0x5A
    p = variant(tmp_path, bytes(bad))
    log = read_log(p)
    assert log.damage and log.of("SessionStarted") and not log.of("RoundEnded")
    first = log.damage[0].part
    for argv in (["rebuild", str(p), "--out", str(tmp_path / "out")], ["replay", str(p), "--verify"]):
        code = main(argv)
        out, err = capsys.readouterr()
        said = out + err
        assert "is cut before" not in said, said
        if argv[0] == "rebuild":
            assert code == 2 and len(err.strip().splitlines()) == 1, err
            assert "holds no whole round: the file is damaged (" in err and first in err, err
        else:  # verify: FAIL, naming the same damage
            assert code != 0 and first in said, said
    assert not (tmp_path / "out").exists()


def _middle_chunk_lost(whole, tmp_path):
    chunks = scan(whole).chunks
    c = chunks[len(chunks) // 2]
    bad = bytearray(whole.read_bytes())
    bad[c.offset + c.length // 2:c.offset + c.length // 2 + 16] = b"\xff" * 16
    return variant(tmp_path, bytes(bad)), f"chunk {c.number} (bytes {c.offset}-{c.offset + c.length})"


def test_a_chunk_lost_in_the_middle_is_verified_up_to_it_and_the_verdict_says_damaged(whole, tmp_path, capsys):
    """A new user's trial: `replay --verify` of a file with a middle chunk overwritten printed DIFFERS lines
    that only followed from the lost chunk, then "verified the whole session" before its FAIL. Now it compares
    up to the lost part, says how many events after it it did not compare, and its verdict says the file is
    damaged (what was lost where, short)."""
    from pairplay.cli.main import main

    p, part = _middle_chunk_lost(whole, tmp_path)
    assert main(["replay", str(p), "--verify"]) == 1
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert "DIFFERS" not in out and "whole session" not in out, out
    assert lines[-1].startswith(f"verify: FAIL: the file is damaged ({part}: its ") and "messages lost" in lines[-1]
    assert lines[-2].startswith("verified up to the damaged part: ") and "after it are not compared" in lines[-2]
    assert out.count(part) == 1 and len(lines[-1]) < 200, out


def test_a_chunk_lost_in_the_middle_is_rebuilt_only_with_partial_its_damage_said_once(whole, tmp_path, capsys):
    """The same file: `rebuild` exited 0 with a PARTIAL policy (its Q-table lacks updates the learner made)
    and printed a 1,500-character damage line twice. Now it is refused in one line unless --partial, and then
    the damage is said once, short."""
    from pairplay.cli.main import main

    p, part = _middle_chunk_lost(whole, tmp_path)
    assert main(["rebuild", str(p), "--out", str(tmp_path / "rb")]) == 2
    out, err = capsys.readouterr()
    assert out == "" and not (tmp_path / "rb").exists()
    [line] = err.splitlines()
    assert line.startswith(f"pairplay rebuild: the file is damaged ({part}: its ") and "--partial" in line, line
    assert line.endswith(f"({p})") and len(line) < 400, line
    assert main(["rebuild", str(p), "--out", str(tmp_path / "rb"), "--partial"]) == 0
    out, err = capsys.readouterr()  # the warning on stderr (cli/main.py `warn`), said once, short
    assert part not in out and err.count(part) == 1 and "PARTIAL session: " in err, (out, err)
    assert len(max(err.splitlines(), key=len)) < 250, err
    assert part in json.loads((tmp_path / "rb" / "damaged.policy.json").read_text())["partial"]


def test_a_view_of_a_file_that_lost_events_is_saved_as_partial_and_names_the_damage(whole, tmp_path, capsys):
    """A new user's trial: `view --recording d.mcap` of a file that lost a middle chunk saved d.rrd, the
    complete view's name (and -q hid the damage warning). It is saved as d.partial.rrd, its line naming the
    damage, as rebuild never passes such a file off as whole."""
    from pairplay.cli.main import main

    p, part = _middle_chunk_lost(whole, tmp_path)
    assert main(["view", "--recording", str(p)]) == 0
    out, err = capsys.readouterr()
    assert not p.with_suffix(".rrd").exists() and (tmp_path / "damaged.partial.rrd").stat().st_size > 0
    [line] = out.splitlines()
    assert line.startswith(f"saved {tmp_path / 'damaged.partial.rrd'}: ") and line.endswith("; partial"), line
    assert f"pairplay view: {p} is damaged ({part}" in err, err  # a warning: on stderr, -q or not (cli/main.py)


def test_a_damage_that_lost_no_event_leaves_the_policy_whole_and_is_said(whole, tmp_path):
    """A new user's trial: a file whose summary alone was damaged (every event read) was rebuilt without
    --partial into a policy flagged PARTIAL, while a lost chunk is refused without it. The policy of a session
    whose every event was read is the learner's: not partial; the damage is still said."""
    data = whole.read_bytes()
    footer_at = len(data) - 8 - 29
    summary_start = struct.unpack_from("<Q", data, footer_at + 9)[0]
    bad = bytearray(data)
    bad[summary_start + 20] ^= 1
    p = variant(tmp_path, bytes(bad), "summary.mcap")
    assert read_log(p).damage and len(read_log(p).events) == len(payloads(whole))
    rebuilt = rebuild_recording(p)
    assert rebuilt.partial == rebuild_recording(whole).partial == "" and not rebuilt.lost
    assert rebuilt.policy == rebuild_recording(whole).policy
    assert rebuilt.damage_read.startswith("the file is damaged, no event lost (")


def undecodable(whole, tmp_path, tag="QUpdated", n=3, name="bad.mcap"):
    """A valid MCAP copy of `whole` whose first `n` messages of event `tag` are bytes that do not decode."""
    p = tmp_path / name
    w = EventLogWriter(p, chunk_size=4096)
    broken = 0
    for r in read_log(whole).events:
        payload = r.payload
        if type(r.event).__name__ == tag and broken < n:
            payload, broken = b'{"type":"broken"', broken + 1
        w.write(r.key, payload, log_time_ns=r.log_time_ns, sequence=r.event.seq)
    w.close()
    assert broken == min(n, sum(type(r.event).__name__ == tag for r in read_log(whole).events))
    return p


def test_messages_that_do_not_decode_are_never_rebuilt_as_whole(whole, tmp_path, capsys):
    """A new user's trial: a valid MCAP file whose QUpdated payloads were partly replaced by bytes that do not
    decode was rebuilt with exit 0, no word, its policy lacking those updates and not flagged partial. Now
    rebuild refuses it in one line unless --partial, as a file that lost a chunk."""
    from pairplay.cli.main import main

    p = undecodable(whole, tmp_path)
    assert len(read_log(p).bad) == 3
    assert main(["rebuild", str(p), "--out", str(tmp_path / "rb")]) == 2
    out, err = capsys.readouterr()
    assert out == "" and not (tmp_path / "rb").exists()
    [line] = err.splitlines()
    assert "3 messages in it do not decode" in line and "--partial" in line, line
    assert main(["rebuild", str(p), "--out", str(tmp_path / "rb"), "--partial", "--no-plot"]) == 0
    assert "do not decode" in json.loads((tmp_path / "rb" / "bad.policy.json").read_text())["partial"]


def test_damaged_index_bytes_between_chunks_lose_no_event_when_the_summary_accounts_for_every_one(whole, tmp_path):
    """A new user's trial: 200 bytes overwritten between two chunks (their Message Index records) lost no
    message, yet verify and rebuild took the part as lost events (rebuild refused it without --partial). The
    summary (its CRC holding) lists every chunk, and its Statistics count every message, metadata record and
    chunk: when everything it lists was read whole, the unreadable bytes held none of it."""
    data = whole.read_bytes()
    chunks = scan(whole).chunks
    c, after = chunks[3], chunks[4]
    assert after.offset > c.offset + c.length  # Message Index records lie between them
    bad = bytearray(data)
    bad[c.offset + c.length:after.offset] = b"\xff" * (after.offset - c.offset - c.length)
    p = variant(tmp_path, bytes(bad), "index.mcap")
    s = scan(p)
    assert s.damage and not [d for d in s.damage if d.lost_at >= 0], s.describe()
    assert any("no message lost" in d.what for d in s.damage), s.describe()
    assert payloads(p) == payloads(whole)
    rebuilt = rebuild_recording(p)
    assert rebuilt.partial == "" and not rebuilt.lost and rebuilt.policy == rebuild_recording(whole).policy
    assert rebuilt.damage_read.startswith("the file is damaged, no event lost (")
    checked = verify_recording(p)  # every event compared; a damaged file still FAILs, saying nothing was lost
    assert not checked.lost_part and checked.not_compared == 0 and "no event lost" in checked.reach


def test_index_bytes_damaged_with_the_summary_damaged_too_are_still_taken_as_lost(whole, tmp_path):
    """Without a summary whose CRC holds, nothing accounts for what the unreadable bytes held: lost."""
    data = whole.read_bytes()
    chunks = scan(whole).chunks
    c, after = chunks[3], chunks[4]
    bad = bytearray(data)
    bad[c.offset + c.length:after.offset] = b"\xff" * (after.offset - c.offset - c.length)
    footer_at = len(data) - 8 - 29
    summary_start = struct.unpack_from("<Q", data, footer_at + 9)[0]
    bad[summary_start + 20] ^= 1
    s = scan(variant(tmp_path, bytes(bad), "both.mcap"))
    assert [d for d in s.damage if d.lost_at >= 0], s.describe()


def test_every_verb_that_reads_a_recording_names_messages_that_do_not_decode(whole, tmp_path, capsys):
    """A new user's trial: after rebuild learned to call undecodable messages damage, `counterfactual` fitted
    such a file with no word and `view` saved it under the complete view's name. Every verb that reads a
    recording says it in rebuild's words (reader.EventLog.undecoded): counterfactual and replay read its
    intact parts and say so, view saves <stem>.partial.rrd, verify fails naming it."""
    from pairplay.cli.main import main

    p = undecodable(whole, tmp_path)
    said = "3 messages in it do not decode (pairplay/dmg/learner/QUpdated: "
    assert main(["counterfactual", str(p), "--fit-only", "--out", str(tmp_path / "cf")]) == 0
    err = capsys.readouterr().err  # warnings about the result: on stderr (cli/main.py `warn`)
    assert f"pairplay counterfactual: {p}: not whole ({said}" in err, err
    assert main(["replay", str(p), "--speed", "max"]) == 0
    err = capsys.readouterr().err
    assert f"pairplay replay: {p}: not whole ({said}" in err, err
    assert main(["replay", str(p), "--verify"]) == 1
    out = capsys.readouterr().out
    assert out.splitlines()[-1].startswith(f"verify: FAIL: the file is damaged ({said}"), out
    assert main(["view", "--recording", str(p)]) == 0
    out, err = capsys.readouterr()
    [line] = out.splitlines()
    assert not p.with_suffix(".rrd").exists() and (tmp_path / "bad.partial.rrd").stat().st_size > 0
    assert line.startswith(f"saved {tmp_path / 'bad.partial.rrd'}: ") and f"pairplay view: {p} is damaged ({said}" in err, err


@pytest.mark.parametrize("verb", [["rebuild", "{p}", "--out", "{tmp}/rb"], ["rebuild", "{p}", "--out", "{tmp}/rb", "--partial"],
                                  ["counterfactual", "{p}", "--out", "{tmp}/cf"], ["replay", "{p}", "--verify"],
                                  ["view", "--recording", "{p}"], ["replay", "{p}", "--speed", "max"]],
                         ids=lambda v: " ".join(v[:1] + v[4:] + v[2:3] if v[0] == "replay" else v[:1] + v[4:]))
def test_a_file_that_yields_no_session_through_its_damage_names_the_damage(whole, tmp_path, capsys, verb):
    """A new user's trial: a recording whose SessionStarted did not decode was "a session that never started".
    When the damage leaves no session, every verb's one line names it (what and where)."""
    from pairplay.cli.main import main

    p = undecodable(whole, tmp_path, "SessionStarted")
    assert main([a.format(p=p, tmp=tmp_path) for a in verb]) == 2
    out, err = capsys.readouterr()
    [line] = err.splitlines()
    assert ("holds no session: " in line and "no SessionStarted in its intact parts: the file is damaged (1 message "
            "in it does not decode (pairplay/dmg/game/SessionStarted: ") in line and str(p) in line, line
    assert sorted(f.name for f in tmp_path.iterdir()) == ["bad.mcap"]


@pytest.mark.parametrize("partial", [False, True])
def test_a_file_whose_round_ends_do_not_decode_is_not_a_session_ended_before_round_1(whole, tmp_path, capsys, partial):
    """A new user's trial: a recording whose RoundEnded messages did not decode was refused as "holds no whole round:
    the session ended (completed) before round 1", the damage unnamed: a session that completed its 3 rounds. The
    line names the damage first (replay/check.py no_whole_round), for rebuild (and the combiner: rebuild_recording)
    with or without --partial."""
    from pairplay.cli.main import main

    p = undecodable(whole, tmp_path, "RoundEnded", n=100)
    assert main(["rebuild", str(p), "--out", str(tmp_path / "rb")] + ["--partial"] * partial) == 2
    [line] = capsys.readouterr().err.splitlines()
    assert ("holds no whole round: the file is damaged (3 messages in it do not decode (pairplay/dmg/game/RoundEnded: "
            in line and "no round of 3 ended in its intact parts; its SessionEnded says completed" in line), line
    with pytest.raises(InputError, match="the file is damaged \\(3 messages in it do not decode"):
        rebuild_recording(p)


@pytest.mark.parametrize("how", ["undecodable", "chunks"])
def test_a_fit_left_no_turn_by_damage_names_the_damage(whole, tmp_path, capsys, how):
    """A new user's trial: `counterfactual` of a heavily damaged file said "holds no resolved turn: nothing to fit
    a user to", the damage unnamed. The line says what is damaged and where."""
    from pairplay.cli.main import main

    if how == "undecodable":
        p, damage = undecodable(whole, tmp_path, "TurnResolved", n=1000), "do not decode (pairplay/dmg/game/TurnResolved: "
    else:
        data = bytearray(whole.read_bytes())
        for c in scan(whole).chunks[1:-1]:  # every chunk's CRC but the first's and the last's fails
            data[c.offset + c.length - 7] ^= 0x5A
        p, damage = variant(tmp_path, bytes(data), "bad.mcap"), "parts lost, the first chunk 1 (bytes "
    assert main(["counterfactual", str(p), "--out", str(tmp_path / "cf")]) == 2
    [line] = capsys.readouterr().err.splitlines()
    assert line.startswith("pairplay counterfactual: holds no resolved turn in its intact parts (") and damage in line, line
    assert not (tmp_path / "cf").exists()


def _curve(path):
    import csv

    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.mark.parametrize("how", ["chunk", "undecodable"])
def test_a_partial_rebuild_s_curve_marks_the_rounds_the_damage_hit(whole, tmp_path, capsys, how):
    """A new user's trial: a `--partial` rebuild's curve.csv did not say which rounds the damage took events of,
    so a researcher read their counts as whole. Its `damaged` column is 1 for exactly the rounds whose events
    were lost (a chunk, or messages that do not decode) and 0 for every other round, whose row is the whole
    file's."""
    from pairplay.cli.main import main

    if how == "chunk":
        p, _ = _middle_chunk_lost(whole, tmp_path)
    else:
        p = undecodable(whole, tmp_path, "TurnResolved", n=2)
    kept = {r.payload for r in read_log(p).events}
    hit = {r.event.round for r in read_log(whole).events if r.payload not in kept and hasattr(r.event, "round")}
    for rec in (whole, p):  # (one run each: one session in two files of a batch is refused, replay/onesession.py)
        assert main(["rebuild", str(rec), "--out", str(tmp_path / "rb"), "--partial", "--no-plot"]) == 0
    capsys.readouterr()
    full = {row["round"]: row for row in _curve(tmp_path / "rb" / "whole.curve.csv")}
    rows = _curve(tmp_path / "rb" / f"{p.stem}.curve.csv")
    assert all(row["damaged"] == "0" for row in full.values())
    marked = {int(row["round"]) for row in rows if row["damaged"] == "1"}
    assert hit and marked == hit & {int(row["round"]) for row in rows}, (marked, hit)
    for row in rows:
        if row["damaged"] == "0":
            assert row == full[row["round"]]


def _round_end_lost(whole, tmp_path, how):
    """A copy of `whole` that lost round 0's RoundEnded: as one message that does not decode (the trial's
    b'{"x":'), or inside the chunk that held it."""
    events = read_log(whole).events
    end = next(r.payload for r in events if type(r.event).__name__ == "RoundEnded" and r.event.round == 0)
    if how == "undecodable-end":
        p = tmp_path / "end.mcap"
        w = EventLogWriter(p, chunk_size=4096)
        for r in events:
            w.write(r.key, b'{"x":' if r.payload == end else r.payload, log_time_ns=r.log_time_ns,
                    sequence=r.event.seq)
        w.close()
        return p
    data = whole.read_bytes()
    for c in scan(whole).chunks:
        bad = bytearray(data)
        bad[c.offset + c.length // 2:c.offset + c.length // 2 + 16] = b"\xff" * 16
        p = variant(tmp_path, bytes(bad), f"chunk{c.number}.mcap")
        if end not in {r.payload for r in read_log(p).events}:
            return p
    raise AssertionError("no chunk holds round 0's RoundEnded")


@pytest.mark.parametrize("how", ["undecodable-end", "chunk-end"])
def test_a_round_whose_end_was_lost_is_the_row_marked_damaged_not_the_next(whole, tmp_path, capsys, how):
    """A new user's trial (16:00): when round 0's RoundEnded was lost (one message that does not decode, or in a
    lost chunk), curve.csv dropped round 0's row and flagged the next, intact round damaged. The round the loss
    hit keeps its row, marked damaged, with what was recorded of it (its turns, picks and matches came only from
    the lost RoundEnded: empty, not 0); an intact round is 0 and its row is the whole file's."""
    from pairplay.cli.main import main

    p = _round_end_lost(whole, tmp_path, how)
    kept = {r.payload for r in read_log(p).events}
    hit = {r.event.round for r in read_log(whole).events if r.payload not in kept and getattr(r.event, "round", -1) >= 0}
    assert 0 in hit
    for rec in (whole, p):  # (one run each: one session in two files of a batch is refused, replay/onesession.py)
        assert main(["rebuild", str(rec), "--out", str(tmp_path / "rb"), "--partial", "--no-plot"]) == 0
    capsys.readouterr()
    full = {row["round"]: row for row in _curve(tmp_path / "rb" / "whole.curve.csv")}
    rows = {row["round"]: row for row in _curve(tmp_path / "rb" / f"{p.stem}.curve.csv")}
    assert set(rows) == set(full), (rows, hit)  # no row dropped: round 0 kept
    assert {int(r) for r, row in rows.items() if row["damaged"] == "1"} == hit
    zero = rows["0"]
    assert (zero["turns"], zero["picks"], zero["matches"]) == ("", "", ""), zero
    float(zero["reward"]), int(zero["learned"]), int(zero["inconsistent"])  # what was read of it: counts, may be partial
    for r, row in rows.items():
        if int(r) not in hit:
            assert row == full[r], (row, full[r])


def test_the_rebuild_figure_draws_each_whole_round_at_its_own_round(whole, tmp_path):
    """Seen beside the curve.csv fault: the figure drew the whole rounds' picks at x = 1, 2, ... in order, so when
    round 0's end was lost, round 1's picks were drawn as round 1 of the figure (round 0's place) and every later
    round one to the left. Each whole round is drawn at its own round (round + 1, as the axis counts from 1)."""
    from pairplay.cli.rebuild import curve_points

    p = _round_end_lost(whole, tmp_path, "undecodable-end")
    full = rebuild_recording(whole).fold
    x, picks = curve_points(rebuild_recording(p).fold)
    assert x == [2, 3] and picks == full.picks_per_round()[1:], (x, picks)
    assert curve_points(full) == ([1, 2, 3], full.picks_per_round())


def test_messages_that_do_not_decode_are_verified_up_to_the_first_and_never_called_the_whole_session(whole, tmp_path,
                                                                                                    capsys):
    """A helper's finding: `replay --verify` of a file whose messages do not decode printed "verified the whole
    session" (and DIFFERS lines that only followed from the missing events) before its FAIL naming them, where a
    lost chunk is verified up to the lost part. A message that does not decode is a lost event: the same."""
    from pairplay.cli.main import main

    p = undecodable(whole, tmp_path)
    assert main(["replay", str(p), "--verify"]) == 1
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert "DIFFERS" not in out and "whole session" not in out, out
    assert lines[-2].startswith("verified up to the damaged part: ") and "after it are not compared" in lines[-2]
    assert lines[-1].startswith("verify: FAIL") and "3 messages in it do not decode" in lines[-1], lines[-1]


def test_a_counterfactual_of_a_damaged_recording_says_so_in_its_files(whole, tmp_path, capsys):
    """A new user's trial: `counterfactual` of a damaged recording said "not whole" on the console only;
    counterfactual.md and the user-model file read as a whole session's fit. Both carry the reader's note
    (reader.EventLog.note): the md's header, the model's `partial`; a whole recording's say nothing."""
    from pairplay.cli.main import main
    from pairplay.replay.reader import read_log
    from pairplay.schemas.usermodel import read_user_model

    p = undecodable(whole, tmp_path)
    note = read_log(p).note
    assert note
    assert main(["counterfactual", str(p), "--policy", "q", "--seeds", "2", "--out", str(tmp_path / "cf")]) == 0
    capsys.readouterr()
    md = (tmp_path / "cf" / "counterfactual.md").read_text()
    head = md.split("## ")[0]
    assert f"**Partial recording:** fitted on the intact parts only ({p.name}: {note})" in head, head
    model = read_user_model(tmp_path / "cf" / f"{p.stem}.usermodel.json")
    assert model.partial == f"{p.name}: {note}"
    assert main(["counterfactual", str(whole), "--fit-only", "--out", str(tmp_path / "cf-whole")]) == 0
    capsys.readouterr()
    assert "Partial" not in (tmp_path / "cf-whole" / "counterfactual.md").read_text()
    assert read_user_model(tmp_path / "cf-whole" / f"{whole.stem}.usermodel.json").partial == ""


def test_a_recovered_file_of_a_chunk_lost_in_the_middle_is_verified_up_to_it_not_claimed_different(
        whole, tmp_path, capsys):
    """A new user's trial: `replay --verify` of what `pairplay recover` made of a file whose middle chunk was
    lost printed DIFFERS for every service: the events after the hole follow lost ones (a pick the game never
    got), artefacts of the loss, not differences. The recovered file now says where its source lost parts
    (recover's metadata), the reader marks a loss there, and verify compares up to it, as for the damaged
    file itself: the same events compared, the same not compared; FAIL naming the part and what it lost."""
    from pairplay.cli.main import main

    p, part = _middle_chunk_lost(whole, tmp_path)
    direct = verify_recording(p)
    done = recover(p, tmp_path / "r.mcap")
    assert main(["replay", str(done.output), "--verify"]) == 1
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert "DIFFERS" not in out and "whole session" not in out and "not recomputed" not in out, out
    # what the source lost, in the reader's words (task agree: "parts lost: ...: the records there" read unfinished)
    assert f"error: recovered from a damaged file (damaged.mcap): {part}: its " in out and "messages lost" in out, out
    assert lines[-2].startswith("verified up to the first part lost from the recording it was recovered from: ")
    again = verify_recording(done.output)
    assert (again.events, again.not_compared, again.lost_part) == (direct.events, direct.not_compared, True)
    log = read_log(done.output)
    assert log.lost_at == read_log(p).lost_at and log.whole  # the same place, in a whole file
    rebuilt = rebuild_recording(done.output)  # and rebuild's curve flags the same rounds as the damaged file's
    assert rebuilt.damaged_rounds == rebuild_recording(p).damaged_rounds != frozenset() and rebuilt.lost


def test_a_recovered_file_whose_damage_lost_no_message_is_verified_whole(whole, tmp_path):
    """The index bytes between two chunks damaged, no message lost (the summary accounts for every one):
    recover makes a whole copy, and `replay --verify` of it said FAIL, "recovered from a damaged file, parts
    lost", and rebuild refused it without --partial, for a session of which nothing was lost."""
    chunks = scan(whole).chunks
    c, after = chunks[3], chunks[4]
    bad = bytearray(whole.read_bytes())
    bad[c.offset + c.length:after.offset] = b"\xff" * (after.offset - c.offset - c.length)
    done = recover(variant(tmp_path, bytes(bad), "index.mcap"), tmp_path / "r.mcap")
    checked = verify_recording(done.output)
    assert checked.ok and not checked.error and "no message was lost" in checked.reach, (checked.error, checked.reach)
    assert not rebuild_recording(done.output).lost


def _summary_start(data: bytes) -> int:
    return struct.unpack_from("<Q", data, len(data) - 8 - 29 + 9)[0]


def _index_length_damaged(whole, tmp_path, cut_in_summary: bool, name: str):
    """`whole` with 0xee written into the length of the first Message Index after chunks 3 and 6 (the bytes up to
    the next chunk do not read), and, if `cut_in_summary`, cut inside its summary (after the Data End): every
    message and the SessionEnded are intact (a new user's trial, trial10)."""
    data = bytearray(whole.read_bytes())
    chunks = scan(whole).chunks
    for c in (chunks[3], chunks[6]):
        assert data[c.offset + c.length] == 0x07  # a Message Index follows the chunk
        data[c.offset + c.length + 1] = 0xEE
    if cut_in_summary:
        data = data[:_summary_start(bytes(data)) + 30]
    return variant(tmp_path, bytes(data), name)


def test_damaged_index_lengths_lose_no_message_even_without_a_summary_to_account_for_them(whole, tmp_path, capsys):
    """trial10: two Message Index lengths damaged and the summary cut: `replay --verify` said "the file is cut
    (a crash?): the session's end is missing; its last events were lost" (the end was there), verified up to
    the first index only, and `recover` of it kept every message yet verify FAILed it ("parts lost") and
    rebuild refused it as partial. The unreadable bytes are exactly the chunk's Message Index records (rebuilt
    from its messages, but for the damaged bytes): no message was there."""
    p = _index_length_damaged(whole, tmp_path, True, "two.mcap")
    s = scan(p)
    assert s.truncated and not [d for d in s.damage if d.lost_at >= 0], s.describe()
    assert sum(d.part.startswith("message index of chunk") and "no message lost" in d.what for d in s.damage) == 2
    assert s.data_complete  # the cut came after the Data End
    assert payloads(p) == payloads(whole)
    from pairplay.cli.main import main

    assert main(["replay", str(p), "--verify"]) == 1  # damaged: FAIL, but every event compared and the end found
    out = capsys.readouterr().out
    assert "a crash?" not in out and "lost" not in out.replace("no message lost", "").replace("no event lost", ""), out
    checked = verify_recording(p)
    assert checked.ended and not checked.lost_part and checked.not_compared == 0 and "no event lost" in checked.reach
    rebuilt = rebuild_recording(p)
    assert rebuilt.partial == "" and not rebuilt.lost and rebuilt.policy == rebuild_recording(whole).policy
    done = recover(p, tmp_path / "two.rec.mcap")
    again = verify_recording(done.output)
    assert again.ok and not again.error and not again.truncated and "no message was lost" in again.reach, (
        again.error, again.reach)
    rebuilt = rebuild_recording(done.output)
    assert rebuilt.partial == "" and not rebuilt.lost and rebuilt.policy == rebuild_recording(whole).policy


def test_index_bytes_followed_by_other_records_are_still_taken_as_lost(whole, tmp_path):
    """Unreadable bytes longer than the chunk's Message Indexes (they held something else too): lost."""
    data = bytearray(whole.read_bytes())
    chunks = scan(whole).chunks
    c, after = chunks[3], chunks[4]
    data[c.offset + c.length + 1] = 0xEE
    data[after.offset + after.length - 7] ^= 0x5A  # the next chunk fails its CRC: the unreadable bytes run past it
    s = scan(variant(tmp_path, bytes(data), "more.mcap"))
    assert any(d.lost_at >= 0 and d.part.startswith("bytes ") for d in s.damage), s.describe()


def test_a_damaged_length_in_the_summary_is_damage_not_a_cut(whole, tmp_path):
    """trial10: a summary record's length damaged (the file whole to its closing magic, every message read)
    was taken as a cut: rebuild printed "PARTIAL session: truncated ..." and flagged the policy partial."""
    data = bytearray(whole.read_bytes())
    data[_summary_start(bytes(data)) + 8] = 0xEE  # the top byte of its first record's length: far past the end
    p = variant(tmp_path, bytes(data), "summary-length.mcap")
    s = scan(p)
    assert not s.truncated and [d.part for d in s.damage] == ["summary"] and "length is damaged" in s.describe()
    rebuilt = rebuild_recording(p)
    assert rebuilt.partial == "" and not rebuilt.lost and rebuilt.damage_read.startswith("the file is damaged, no event lost")
    checked = verify_recording(p)  # damaged after the data section only: PASS, the damage said (task agree)
    assert not checked.truncated and not checked.lost_part and checked.ok and "no event lost" in checked.verdict


def test_recovering_a_file_that_lost_no_message_never_makes_its_policy_partial(whole, tmp_path):
    """trial10: a file whose only damage was a Message Index rebuilt whole, but after `recover` its policy said
    "PARTIAL ... completed by pairplay recover": recovering made it worse. The same for a file cut inside its
    summary (its data section complete): rebuilt and verified as whole, after recover as before."""
    only_index = _index_length_damaged(whole, tmp_path, False, "index.mcap")
    data = whole.read_bytes()
    cut = variant(tmp_path, data[:_summary_start(data) + 30], "cut-summary.mcap")
    for p in (only_index, cut):
        assert rebuild_recording(p).partial == "", p
        done = recover(p, tmp_path / f"{p.stem}.rec.mcap")
        rebuilt = rebuild_recording(done.output)
        assert rebuilt.partial == "" and not rebuilt.lost and rebuilt.policy == rebuild_recording(whole).policy, (
            p, rebuilt.partial)
        checked = verify_recording(done.output)
        assert checked.ok and not checked.truncated and not checked.error, (p, checked.verdict)
    whole_cut = rebuild_recording(cut)
    assert whole_cut.damage_read.startswith("the file is cut after its data section, no event lost (")


def test_a_study_game_whose_file_is_cut_after_its_data_section_lost_nothing(whole, tmp_path):
    """The study's game end (replay/studydata.py `recording_damage`, `lost_answers`) took any cut as lost events
    ("truncated: ...: no policy built"); a cut inside the summary, after the Data End, lost none."""
    from pairplay.replay.studydata import lost_answers, recording_damage

    data = whole.read_bytes()
    log = read_log(variant(tmp_path, data[:_summary_start(data) + 30], "cut-summary.mcap"))
    assert log.truncated and len(log.events) == len(payloads(whole))
    assert recording_damage(log) == "" and lost_answers(log, False, True) == []
    earlier = read_log(variant(tmp_path, data[:len(data) // 2], "cut-data.mcap"))  # a cut in the data: a loss
    assert recording_damage(earlier).startswith("truncated: ") and lost_answers(earlier, False, True)


def test_a_recovered_file_of_a_chunk_lost_is_partial_to_every_verb_that_reads_damage(whole, tmp_path, capsys):
    """A new user's trial: what `pairplay recover` made of a file that lost a chunk is whole, and only verify and
    rebuild read its metadata saying where its source lost parts: `view` saved it as the complete view ("0
    notes"), `counterfactual` fitted it with no "Partial recording" line. The reader carries the source's losses
    (EventLog.source_lost, in `note` and `lost`), so every verb says them as it says a damaged file's."""
    from pairplay.cli.main import main
    from pairplay.schemas.usermodel import read_user_model

    p, part = _middle_chunk_lost(whole, tmp_path)
    r = recover(p, tmp_path / "r.mcap").output
    log = read_log(r)
    assert log.whole and not log.damaged
    said = f"recovered from a damaged file ({p.name}): {part}: its "
    assert log.note.startswith(said) and log.lost == log.note and "messages lost" in log.note, log.note
    assert main(["view", "--recording", str(r)]) == 0
    out, err = capsys.readouterr()
    [line] = out.splitlines()
    assert not r.with_suffix(".rrd").exists() and (tmp_path / "r.partial.rrd").stat().st_size > 0
    assert line.startswith(f"saved {tmp_path / 'r.partial.rrd'}: ") and f"pairplay view: {r} was {said}" in err, err
    assert main(["counterfactual", str(r), "--fit-only", "--out", str(tmp_path / "cf")]) == 0
    capsys.readouterr()
    head = (tmp_path / "cf" / "counterfactual.md").read_text().split("## ")[0]
    assert f"**Partial recording:** fitted on the intact parts only ({r.name}: {said}" in head, head
    assert read_user_model(tmp_path / "cf" / "r.usermodel.json").partial.startswith(f"{r.name}: {said}")
    assert said in rebuild_recording(r).lost
    assert any(note and said in note for _, note in recording_items(r))


def test_a_recovered_file_whose_damage_lost_no_message_is_whole_to_every_verb(whole, tmp_path, capsys):
    """The other side of the rule: a recovered file whose source's damage lost no message (index bytes between
    two chunks) holds the whole session, and no verb calls it partial."""
    from pairplay.cli.main import main

    chunks = scan(whole).chunks
    c, after = chunks[3], chunks[4]
    bad = bytearray(whole.read_bytes())
    bad[c.offset + c.length:after.offset] = b"\xff" * (after.offset - c.offset - c.length)
    r = recover(variant(tmp_path, bytes(bad), "index.mcap"), tmp_path / "r.mcap").output
    log = read_log(r)
    assert log.whole and (log.note, log.lost, log.source_lost, log.damaged) == ("", "", "", "")
    assert main(["view", "--recording", str(r)]) == 0
    [line] = capsys.readouterr().out.splitlines()
    assert (tmp_path / "r.rrd").stat().st_size > 0 and "partial" not in line, line
    assert main(["counterfactual", str(r), "--fit-only", "--out", str(tmp_path / "cf")]) == 0
    capsys.readouterr()
    assert "Partial" not in (tmp_path / "cf" / "counterfactual.md").read_text()
    assert not rebuild_recording(r).lost
    assert not any(note for _, note in recording_items(r))


def test_a_file_whose_damage_lost_no_message_is_whole_to_counterfactual_view_and_replay(whole, tmp_path, capsys):
    """trial11: a file whose Message Index lengths are damaged and that is cut after its Data End loses no message,
    yet counterfactual ("not whole ...; fitting the turns of its intact parts", a Partial line, the model
    partial), view ("recording not whole") and replay said it lacked something: they read `note` (any damage), not
    what was lost (`EventLog.missing`). A file that lost events still says so in all three."""
    from pairplay.cli.main import main
    from pairplay.replay.reader import read_log
    from pairplay.schemas.usermodel import read_user_model
    from pairplay.services.view.sources import recording_items

    p = _index_length_damaged(whole, tmp_path, cut_in_summary=True, name="loss-free.mcap")
    log = read_log(p)
    assert log.note and not log.missing  # damaged, nothing lost
    assert main(["counterfactual", str(p), "--fit-only", "--out", str(tmp_path / "cf")]) == 0
    out = capsys.readouterr().out
    assert "not whole" not in out, out
    assert "Partial" not in (tmp_path / "cf" / "counterfactual.md").read_text()
    assert read_user_model(tmp_path / "cf" / f"{p.stem}.usermodel.json").partial == ""
    notes = [note for _e, note in recording_items(p) if note]
    assert not [n for n in notes if "not whole" in n], notes
    lost = undecodable(whole, tmp_path)
    assert read_log(lost).missing
    assert [n for _e, n in recording_items(lost) if n and "not whole" in n]


@pytest.mark.parametrize("zeroed", ["magic", "footer-crc", "footer", "summary-tail", "summary"])
def test_a_zeroed_footer_or_summary_is_damage_that_verify_names_though_every_message_reads(whole, tmp_path, capsys,
                                                                                          zeroed):
    """Task rec2 (3): the last N bytes of a recording zeroed (its closing magic, its footer's CRC, the footer, the
    summary's tail, the whole summary). Every message is in the data section, proved by its chunks' CRCs and the
    Data End's CRC, so none is lost; but the summary and footer are parts of the file, and a zeroed one is damage
    (mcapscan's rule: what a reader can trust): `replay --verify` names it, never silent; it PASSes (task agree: the
    verbs agree no event is lost, every one is compared), the damage said after the PASS."""
    from pairplay.cli.main import main

    data = whole.read_bytes()
    start = _summary_start(data)
    n = {"magic": 8, "footer-crc": 12, "footer": 37, "summary-tail": 100, "summary": len(data) - start}[zeroed]
    p = variant(tmp_path, data[:-n] + b"\0" * n, f"zeroed-{n}.mcap")
    log = read_log(p)
    assert not log.whole and log.data_complete and not log.truncated and not log.missing
    assert payloads(p) == payloads(whole)  # every message read
    part = "file end" if n <= 20 else "summary"
    # task agree: every event is as recorded (the chunks' and the Data End's CRCs) and compared: PASS, never silent,
    # the damage said in the words every verb says it (reader.EventLog.loss_free; it was a FAIL here, exit 0 and
    # whole to rebuild, view and counterfactual)
    assert main(["replay", str(p), "--verify"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[-1] == f"verify: PASS; {log.loss_free}", lines[-1]
    assert log.loss_free.startswith(f"the file is damaged, no event lost ({part}: "), log.loss_free


@pytest.mark.parametrize("head", ["zeroed", "length"])
def test_a_chunk_whose_record_head_is_unreadable_is_one_finding_not_every_later_chunk_out_of_order(
        whole, tmp_path, capsys, head):
    """Task rec3 item 2: chunk 7's record head (opcode and length, 9 bytes) zeroed, or its length alone damaged.
    The scan reads on from the next chunk that proves itself, but it numbered the chunks it found, so the
    summary's index had every later chunk "indexed as chunk N+1: chunks out of order" (~30 findings, a line of
    2,000 characters from recover). Now the summary's Chunk Index names the unreadable bytes as chunk 7, its
    messages are counted from its Message Index records (intact after it), and the one damage is said once with
    its consequence; the later chunks are in order, as they are."""
    from pairplay.cli.main import main

    chunks = scan(whole).chunks
    c = chunks[7]
    bad = bytearray(whole.read_bytes())
    if head == "zeroed":
        bad[c.offset:c.offset + 9] = bytes(9)
    else:
        bad[c.offset + 1:c.offset + 9] = struct.pack("<Q", 2**40)
    p = variant(tmp_path, bytes(bad))
    s = scan(p)
    assert "out of order" not in s.describe() and "chunk index" not in s.describe(), s.describe()
    [lost] = [d for d in s.damage if d.lost_at >= 0]
    assert lost.part.startswith(f"chunk 7 (bytes {c.offset}-") and lost.lost == f"its {len(c.messages)} messages"
    assert f"{len(chunks) - 8} later chunks read" in lost.what, lost.what
    assert [d.part for d in s.damage if d is not lost] == ["data section"], s.describe()  # the CRC the lost bytes break
    assert len(s.lost_chunks) == 1 and [x.number for x in s.chunks] == list(range(len(chunks)))
    assert len(read_log(p).events) == len(read_log(whole).events) - len(c.messages)
    assert main(["recover", str(p), "-o", str(tmp_path / "r.mcap")]) == 0
    [line] = capsys.readouterr().out.splitlines()
    assert line.count("chunk 7 (") == 2 and f"{len(c.messages)} messages lost" in line and len(line) < 700, line
    meta = read_log(tmp_path / "r.mcap").metadata["pairplay.recovered"]
    assert meta["lost_chunks"] == "1" and [d.split(":")[0] for d in json.loads(meta["damaged"])] == [
        lost.part, "data section"]
    assert main(["replay", str(p), "--verify"]) == 1
    verdict = capsys.readouterr().out.splitlines()[-1]
    assert verdict.startswith("verify: FAIL: the file is damaged (chunk 7 (") and "more finding" not in verdict, verdict
