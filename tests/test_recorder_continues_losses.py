"""A recorder restarted within the live session copies what its predecessor's recording holds into its own file,
"so this file alone holds the whole session" (services/recorder.py `_continue`). When the earlier file lost
messages its journal cannot give back (a damaged chunk with no journal beside it, or a file that is itself a
recovered one with recorded losses), the new file recorded no loss: every verb took the session as whole. Now
the continuing recorder records what the earlier file lost in the metadata `pairplay recover` writes
(replay/reader.py RECOVERED, `carry_recovery`), so every verb says "partial" the same way; a predecessor whose
journal holds what the damage lost, or that lost nothing, stays whole.

Real parts: a real recording (the recorder's writer, small chunks) damaged on disk as a disk would, a real
journal beside it (replay/wal.py JournalWriter), a real Recorder restarted on it, the real verbs."""

from __future__ import annotations

import shutil

from pairplay.replay.mcapscan import scan
from pairplay.replay.reader import read_any_log, read_log
from pairplay.replay.recover import recover
from pairplay.replay.wal import JournalWriter
from pairplay.services.recorder import Recorder
from pairplay.services.verify import verify_recording

from damageutil import damage, small_chunked_session


def _continued(path, session: str):
    """A recorder restarted on the session's recording at `path` (bus-less: its copy is all it writes), closed."""
    rec = Recorder(None, session, path, restart=True)
    rec.close()
    return rec.path


def _lost_part(path) -> str:
    [d] = [d for d in scan(path).damage if d.lost_at >= 0]
    return d.part


def test_a_continued_file_says_what_its_damaged_predecessor_lost_to_every_verb(tmp_path, capsys):
    from pairplay.cli.main import main

    earlier = small_chunked_session(tmp_path / "c1.mcap", "c1")
    whole = read_log(earlier)
    damage(earlier, "chunk")  # closed, then damaged on disk: no journal beside it gives the chunk back
    part = _lost_part(earlier)
    held = len(read_log(earlier).events)
    new = _continued(tmp_path / "c1.mcap", "c1")
    log = read_log(new)
    assert log.whole and len(log.events) == held  # the file itself is whole: what it copied is all there
    assert log.lost and part in log.lost and "c1.mcap" in log.lost, log.lost
    assert log.missing and log.lost_from >= 0
    direct = verify_recording(earlier)
    v = verify_recording(new)  # compared up to where the chunk was, as the damaged file is
    assert not v.ok and v.lost_part and (v.events, v.not_compared) == (direct.events, direct.not_compared)
    assert main(["replay", str(new), "--verify"]) == 1
    out = capsys.readouterr().out
    # what its predecessor lost, in the reader's words (task agree: reader.EventLog.source_lost)
    assert f"error: {log.source_lost}" in out and f"{part}: its " in out and "DIFFERS" not in out, out
    assert main(["rebuild", str(new), "--out", str(tmp_path / "rb")]) == 2  # refused without --partial
    err = capsys.readouterr().err
    assert part in err and "--partial" in err, err
    # where the chunk was: the messages before it compared, the mark at the same place as in the damaged file
    assert log.lost_from == read_log(earlier).lost_from and len(whole.events) > held


def test_verify_of_a_continued_file_names_the_recording_it_continues_not_one_it_was_recovered_from(tmp_path, capsys):
    """A new user's trial: `replay --verify` of a restarted recorder's file (a continued file, no recovered one) said
    "verified up to the first part lost from the recording it was recovered from": words that fit what the file is
    (reader.said_source), as its error line says "continues a damaged recording"."""
    from pairplay.cli.main import main

    earlier = small_chunked_session(tmp_path / "c7.mcap", "c7")
    damage(earlier, "chunk")
    new = _continued(tmp_path / "c7.mcap", "c7")
    assert main(["replay", str(new), "--verify"]) == 1
    out = capsys.readouterr().out
    assert "verified up to the first part lost from the recording it continues: " in out, out
    assert "recovered" not in out, out


def _journaled_then_damaged(tmp_path, session: str, chunk: int):
    """A finished recording with its recorder's journal beside it (all it received, as a recorder killed after
    its last flush leaves it), then the chunk at `chunk` damaged (its CRC fails); what the journal holds."""
    earlier = small_chunked_session(tmp_path / f"{session}.mcap", session)
    journaled = [(r.key, r.payload) for r in read_log(earlier).events]
    journal = JournalWriter(earlier, session)
    for item in journaled:
        journal.add(item)
    journal.write_pending()
    journal.close(remove=False)
    c = scan(earlier).chunks[chunk]
    data = bytearray(earlier.read_bytes())
    data[c.offset + c.length - 7] ^= 0x5A
    earlier.write_bytes(bytes(data))
    return journaled


def test_a_predecessor_whose_journal_gives_back_what_its_damage_lost_stays_whole(tmp_path):
    """Its last chunk lost: the journal's records after the last message read are what it held, and the live
    checks take them (they come after everything the file holds)."""
    journaled = _journaled_then_damaged(tmp_path, "c2", -1)
    new = _continued(tmp_path / "c2.mcap", "c2")
    log = read_log(new)
    assert log.whole and not log.lost and not log.missing, log.lost
    assert sorted(r.payload for r in log.events) == sorted(p for _, p in journaled)


def test_a_middle_chunk_its_journal_holds_but_the_live_checks_refuse_is_still_lost(tmp_path):
    """A middle chunk lost: the journal holds its events, but after the later ones the file holds the live checks
    refuse them as out of order (recorded as refusals, not events): the session lacks them, and the file says so."""
    _journaled_then_damaged(tmp_path, "c5", 10)
    part = _lost_part(tmp_path / "c5.mcap")
    new = _continued(tmp_path / "c5.mcap", "c5")
    log = read_log(new)
    assert log.metadata["pairplay.recorder.journal"]["taken"] == "0"
    assert part in log.lost and log.missing, log.lost


def test_a_predecessor_that_lost_nothing_stays_whole(tmp_path):
    earlier = small_chunked_session(tmp_path / "c3.mcap", "c3")
    new = _continued(tmp_path / "c3.mcap", "c3")
    log = read_log(new)
    assert log.whole and not log.lost and "pairplay.recovered" not in log.metadata
    assert verify_recording(new).ok


def test_a_predecessor_that_is_a_recovered_file_keeps_its_losses_and_a_second_restart_too(tmp_path):
    source = small_chunked_session(tmp_path / "src.mcap", "c4")
    damage(source, "chunk")
    part = _lost_part(source)
    recover(source, tmp_path / "src.recovered.mcap")
    shutil.move(tmp_path / "src.recovered.mcap", tmp_path / "c4.mcap")  # the recovered file is the session's now
    assert part in read_log(tmp_path / "c4.mcap").lost
    new = _continued(tmp_path / "c4.mcap", "c4")
    assert part in read_log(new).lost and not verify_recording(new).ok, read_log(new).lost
    again = _continued(tmp_path / "c4.mcap", "c4")  # restarted once more: the losses carried again
    assert again.name == "c4.2.mcap" and read_log(again).lost.count(part) == 1, read_log(again).lost
    assert read_log(again).lost_at == read_log(new).lost_at


def test_a_second_restart_says_the_first_damage_once(tmp_path):
    earlier = small_chunked_session(tmp_path / "c7.mcap", "c7")
    damage(earlier, "chunk")
    part = _lost_part(earlier)
    first = _continued(tmp_path / "c7.mcap", "c7")
    again = _continued(tmp_path / "c7.mcap", "c7")  # reads c7.mcap (damaged) and c7.1.mcap (which carries it)
    said = read_log(again).lost
    assert again.name == "c7.2.mcap" and said.count(part) == 1, said
    assert read_log(again).lost_at == read_log(first).lost_at


def test_the_continued_file_says_it_continues_a_damaged_recording_and_recover_carries_it(tmp_path):
    earlier = small_chunked_session(tmp_path / "c6.mcap", "c6")
    damage(earlier, "chunk")
    part = _lost_part(earlier)
    new = _continued(tmp_path / "c6.mcap", "c6")
    assert read_log(new).lost.startswith(f"continues a damaged recording (c6.mcap): {part}: its "), read_log(new).lost
    data = bytearray(new.read_bytes())  # the continued file's footer zeroed, then recovered: the loss carried
    data[-37:] = bytes(37)
    (tmp_path / "cut.mcap").write_bytes(bytes(data))
    done = recover(tmp_path / "cut.mcap", tmp_path / "r.mcap")
    said = read_log(done.output).lost
    assert said.startswith("recovered from a damaged file (cut.mcap, itself recovered from c6.mcap)") and part in said, said


def test_a_live_restart_whose_refill_gives_back_the_damaged_chunk_stays_whole(tmp_path):
    """The live path: a recorder SIGKILLed mid-session, a middle chunk of its file damaged and its journal
    removed before the restart. The restarted recorder's refill asks the services for what they published after
    the hole and writes it into the hole (`_fill_hole`): every event the damaged file held is in the new file, and
    the loss is not recorded (`_note_earlier_lost`: holes filled, as many as the chunk held, none left)."""
    import signal

    from busutil import wait_until
    from pairplay.replay.wal import wal_path
    from test_faults import endpoint_of, first_line, session_proc
    from test_recorder_restart import recorder

    s = "lv"
    p = session_proc(tmp_path, "--participant", "sim:ashley", "--rounds", "5000", "--session", s,
                     "--external", "recorder")
    first = second = None
    try:
        endpoint = endpoint_of(first_line(p))
        first = recorder(tmp_path, s, endpoint)
        f = tmp_path / f"{s}.mcap"
        assert wait_until(lambda: f.exists() and len(scan(f).chunks) >= 3, 120, 0.2)
        first.send_signal(signal.SIGKILL)
        first.wait(10)
        chunks = scan(f).chunks
        c = chunks[len(chunks) // 2]
        held = {r.payload for r in read_log(f).events}
        data = bytearray(f.read_bytes())
        data[c.offset + c.length - 7] ^= 0x5A
        f.write_bytes(bytes(data))
        wal_path(f).unlink()
        assert read_log(f).lost
        second = recorder(tmp_path, s, endpoint)
        new = tmp_path / f"{s}.1.mcap"
        assert wait_until(lambda: second.poll() is not None or (new.exists() and read_any_log(new).of("RecordingGap")),
                          120, 0.3)
        p.send_signal(signal.SIGTERM)
        p.communicate(timeout=60)
        assert second.wait(timeout=30) == 0, second.stderr.read()
    finally:
        for proc in (p, first, second):
            if proc is not None and proc.poll() is None:
                proc.kill()
                proc.communicate()
    log = read_log(new)
    missing = held - {r.payload for r in log.events}
    assert not missing, sorted(m[:160] for m in missing)  # (what is missing, said)
    assert not log.lost and "pairplay.recovered" not in log.metadata, log.lost
