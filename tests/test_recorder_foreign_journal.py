"""A restarted recorder takes the journal beside the earlier file only if it is that recording's.

A journal names the recording it journals by the `started_ns` of that recording's own metadata
(replay/wal.py RECORDING_STARTED). Before, a recorder restarted within a live session (`pairplay run recorder`
again) took the journal beside the session's earlier file by session id alone (services/recorder.py
`earlier_records`): a journal another recording of the same id left there (a killed recorder's, moved or
given back its name with the file it was not) had its records merged into the continuing file, the ones the
live checks took as events and the rest as the recorder's refusals. Now it is not taken, its account says
whose it is, and it stays where it was, for the user (`pairplay recover` names it too: NotItsJournal).

Real parts: two sessions of one id, each with its own `pairplay run recorder` SIGKILLed mid-game; the first's
journal is set beside the second's file, whose recorder is then restarted on the live session."""

from __future__ import annotations

import signal
from pathlib import Path

from pairplay.replay.reader import read_any_log, read_log
from pairplay.replay.wal import RECORDING_STARTED, read_journal, wal_path

from busutil import wait_until
from test_faults import endpoint_of, first_line, session_proc
from test_recorder_restart import recorder

SESSION = "fj"


def _game_session(folder: Path):
    return session_proc(folder, "--participant", "sim:ashley", "--rounds", "5000", "--session", SESSION,
                        "--external", "recorder")


def _stop(*procs) -> None:
    for proc in procs:
        if proc is not None and proc.poll() is None:
            proc.kill()
            proc.communicate()


def _journal_left_by_a_killed_recorder(folder: Path) -> Path:
    """The journal a SIGKILLed recorder of SESSION left in `folder` once it held some of the game's events; its
    session then stopped."""
    folder.mkdir()
    journal = wal_path(folder / f"{SESSION}.mcap")
    p, rec = _game_session(folder), None
    try:
        rec = recorder(folder, SESSION, endpoint_of(first_line(p)))
        assert wait_until(lambda: journal.exists() and sum(k.split("/")[2] == "game" for k, _, _ in
                                                           read_journal(journal).records) >= 50, 60), "no journal"
        rec.send_signal(signal.SIGKILL)
        rec.wait(10)
        p.send_signal(signal.SIGTERM)
        p.communicate(timeout=60)
    finally:
        _stop(p, rec)
    return journal


def test_a_restarted_recorder_leaves_another_recordings_journal_of_its_session_id_untaken(tmp_path):
    foreign = _journal_left_by_a_killed_recorder(tmp_path / "other")
    theirs = read_journal(foreign)
    path = tmp_path / f"{SESSION}.mcap"
    p = _game_session(tmp_path)
    first = second = None
    try:
        endpoint = endpoint_of(first_line(p))
        first = recorder(tmp_path, SESSION, endpoint)
        assert wait_until(lambda: path.exists() and read_any_log(path).of("SessionStarted"), 60), "nothing flushed"
        first.send_signal(signal.SIGKILL)
        first.wait(10)
        wal_path(path).unlink()  # its own journal gone, the other recording's beside it in its place
        foreign.rename(wal_path(path))
        second = recorder(tmp_path, SESSION, endpoint)
        restarted = tmp_path / f"{SESSION}.1.mcap"
        assert wait_until(lambda: second.poll() is not None or restarted.exists() and bool(
            read_any_log(restarted).of("RecordingGap")), 120, 0.1)
        assert second.poll() is None, second.stderr.read()
        p.send_signal(signal.SIGTERM)
        p.communicate(timeout=60)
        assert second.wait(timeout=30) == 0, second.stderr.read()
        said = second.stderr.read()
    finally:
        _stop(p, first, second)
    # said once: the recorder read the earlier recordings twice (is it the same live session; then its copy),
    # and each reading logged its warning
    assert said.count("is not taken") == 1, said
    log = read_log(restarted)
    assert log.whole
    account = log.metadata["pairplay.recorder.journal"]
    assert account["earlier_journal"] == f"{SESSION}.mcap.journal"
    assert "not_read" in account and "taken" not in account, account
    assert "another recording of session 'fj'" in account["not_read"], account
    # nothing of it is in the file, as an event or as a refusal
    payloads = {r.payload for r in log.events}
    assert not [k for k, p, _ in theirs.records if p in payloads and k.split("/")[2] != "recorder"]
    refused = [e.reason for e in log.of("MessageRejected")  # (the end's, as test_recorder_restart allows them)
               if "not reported" not in e.reason and not e.reason.startswith("the session is over; ")]
    assert not refused, refused[:5]
    # it is left where it was, whole, for the user (recover names it as another recording's)
    assert read_journal(wal_path(path)).header[RECORDING_STARTED] == theirs.header[RECORDING_STARTED]
    assert len(log.of("SessionStarted")) == 1


def test_a_cut_games_end_is_never_read_from_another_recordings_journal(tmp_path):
    """A study game cut before its end (replay/cutgame.py `cut_end`) read its SessionEnded from the journal beside
    its file by session id alone: another recording's journal of the id there gave the game that recording's end
    (journaled completed, its step not played again). Now only the file's own journal is read (or one written
    before journals named their recording, as before). Real parts: a recorded game's MCAP, cut inside the chunk
    of its end, and a real journal beside it."""
    import shutil

    from pairplay.replay.cutgame import CUT_BEFORE_END, cut_end
    from pairplay.replay.mcapscan import scan
    from pairplay.replay.wal import RECORDER_METADATA, JournalWriter

    path = tmp_path / "sample-sim-ashley.mcap"
    shutil.copy(Path(__file__).parent.parent / "recordings" / "samples" / "sim-ashley-fmt2.mcap", path)
    log = read_log(path)
    session, started = log.metadata[RECORDER_METADATA]["session"], int(log.metadata[RECORDER_METADATA]["started_ns"])
    [end] = [r.log_time_ns for r in log.events if type(r.event).__name__ == "SessionEnded"]
    [chunk] = [c for c in scan(path).chunks if any(t == end for _, _, t in c.messages)]
    path.write_bytes(path.read_bytes()[:chunk.offset + chunk.length // 2])  # inside the chunk of its end
    assert not read_any_log(path).of("SessionEnded") and read_any_log(path).metadata[RECORDER_METADATA]

    def with_journal(recording_started_ns):
        wal_path(path).unlink(missing_ok=True)
        journal = JournalWriter(path, session, recording_started_ns=recording_started_ns)
        for r in log.events:
            journal.add((r.key, r.payload))
        journal.close()
        return cut_end(path, path, session)

    foreign = with_journal(started + 1)
    assert (foreign.ended, foreign.reason, foreign.answered) == (None, CUT_BEFORE_END, False), foreign
    for own in (started, None):  # its own journal, or one older than the key: its end is read there, as before
        cut = with_journal(own)
        assert cut.outcome == "completed" and cut.where == "its recorder's journal beside it", (own, cut)
