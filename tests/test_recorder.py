"""The recorder's own rules, without a network: it writes what passes the
checks, refuses the rest with a reason, never overwrites a recording, and puts
the session config into the file's metadata."""

import pytest

from pairplay.replay.reader import read_log
from pairplay.schemas import events as ev
from pairplay.schemas.envelope import stamped
from pairplay.schemas.events import encode_event
from pairplay.schemas.keys import event_key
from pairplay.schemas.session import SessionConfig
from pairplay.services.recorder import Recorder, RecordingExists


def message(event, source="game", seq=1, session="r1"):
    e = stamped(event, session=session, source=source, seq=seq, time_ns=seq)
    return event_key("r1", source, type(event).__name__), encode_event(e)


def flooding(path):
    """A recorder of session r1 whose SessionStarted (game seq 1) is written and whose inbox sheds a source's
    second waiting message (a flood's worth)."""
    rec = Recorder(None, "r1", path)
    rec.inbox.per_source = 1
    cfg = SessionConfig(session="r1", participant="sim:ashley", persona="ashley", seed=9, rounds=1)
    assert rec.record(*message(ev.SessionStarted(config=cfg)), 1)
    return rec


def test_the_recorder_keeps_good_messages_and_refuses_bad_ones(tmp_path):
    rec = Recorder(None, "r1", tmp_path / "r1.mcap", clock=iter(range(10**9, 10**10)).__next__)
    cfg = SessionConfig(session="r1", participant="sim:ashley", persona="ashley", seed=9, rounds=1,
                        software_version="9.9")
    assert rec.record(*message(ev.SessionStarted(config=cfg)), 1)
    assert rec.record(*message(ev.RoundStarted(round=0, faces=[i // 2 for i in range(18)]), seq=2), 2)
    assert not rec.record(*message(ev.RoundStarted(round=0, faces=[]), seq=2), 3)  # duplicate seq
    assert not rec.record(event_key("r1", "game", "RoundStarted"), b"{oops", 4)  # malformed
    key, payload = message(ev.RoundEnded(round=0, turns=9, matches=9), seq=3)
    assert not rec.record(key.replace("RoundEnded", "RoundStarted"), payload, 5)  # key disagrees
    assert not rec.record(*message(ev.SessionEnded(), seq=4, session="r2"), 6)  # wrong session
    assert rec.rejected == 4
    rec.close()
    log = read_log(tmp_path / "r1.mcap")
    kept = [type(r.event).__name__ for r in log.events if r.event.source != "recorder"]
    assert kept == ["SessionStarted", "RoundStarted"]
    refusals = [r.event for r in log.events if r.event.source == "recorder"]
    assert len(refusals) == 4 and all(isinstance(e, ev.MessageRejected) and e.reason for e in refusals)
    assert log.metadata["pairplay.session"]["seed"] == "9"
    assert log.metadata["pairplay.session"]["software_version"] == "9.9"


def test_a_recording_is_never_overwritten(tmp_path):
    first = Recorder(None, "r1", tmp_path / "r1.mcap")
    first.close()
    with pytest.raises(RecordingExists):  # a new session: the id is taken
        Recorder(None, "r1", tmp_path / "r1.mcap")
    second = Recorder(None, "r1", tmp_path / "r1.mcap", restart=True)  # restarted within the live session
    second.close()
    assert first.path.name == "r1.mcap" and second.path.name == "r1.1.mcap"


def test_a_close_past_its_deadline_still_writes_the_session_end_it_holds_and_counts_the_rest(tmp_path):
    """Past its deadline a recorder's close sheds what is still queued (a flood must not hold up the exit),
    counted; it shed the session's SessionEnded with it, already in hand: a starved `run recorder` (the
    signal's deadline gone before it ran on) finished a file that does not say how its session ended. The
    end is written; the rest is counted, as before."""
    from pairplay.services.bus import Deadline

    rec = Recorder(None, "r1", tmp_path / "r1.mcap")
    cfg = SessionConfig(session="r1", participant="sim:ashley", persona="ashley", seed=9, rounds=1)
    assert rec.record(*message(ev.SessionStarted(config=cfg)), 1)
    rec.inbox.put(*message(ev.RoundStarted(round=0, faces=[i // 2 for i in range(18)]), seq=2))
    rec.inbox.put(*message(ev.SessionEnded(reason="interrupted", detail="SIGTERM"), seq=3))
    assert rec.close(stopped_by="SIGTERM", deadline=Deadline(0.0)) is None
    log = read_log(tmp_path / "r1.mcap")
    assert [type(r.event).__name__ for r in log.events if r.event.source == "game"] == ["SessionStarted",
                                                                                      "SessionEnded"]
    end = log.metadata["pairplay.recorder.end"]
    assert (end["session_ended"], end["unrecorded_at_exit"]) == ("true", "1"), end
    [shed] = [r.event for r in log.events if isinstance(r.event, ev.MessageRejected)]
    assert "still queued when the recording stopped" in shed.reason and shed.offending_source == "game"
    # the hole it left below the end (seq 2) is said as shed at the exit, counted there once: not lost on the bus
    # (test_a_hole_the_exit_shed_is_said_once_under_its_cause_and_a_hole_of_the_bus_apart)
    lost = log.metadata["pairplay.recovered"]
    assert "bus" not in lost and (lost["lost_count"], lost["shed_count"]) == ("0", "1"), lost
    assert "lost on the bus" not in log.missing and log.missing.startswith(
        "events its recorder shed at the exit (still queued when the recording stopped) (r1.mcap): game seq 2 "), log.missing
    assert log.lost_at == [1]  # the place is still marked: every verb says the session is partial there


def test_a_hole_the_exit_shed_is_said_once_under_its_cause_and_a_hole_of_the_bus_apart(tmp_path):
    """An external recorder (`pairplay run recorder`) whose close sheds its inbox (a flood, or the signal's deadline
    passed) keeps the session's end: the events shed below it leave a hole. That hole was recorded as "lost on the
    bus" (they came, and were shed) and counted twice: once as shed (the MessageRejected count, `unrecorded_at_exit`),
    once as lost (`lost_count`). Now it is said as shed at the exit, counted once (`shed_count` names those of the
    shed count that left a hole; `lost_count` only the bus's), and a hole the bus left beside it is still the bus's;
    verify and every reader (reader.EventLog.missing) say each under its cause."""
    import json

    from pairplay.services.bus import Deadline
    from pairplay.services.verify import verify_recording

    rec = Recorder(None, "r1", tmp_path / "r1.mcap")
    cfg = SessionConfig(session="r1", participant="sim:ashley", persona="ashley", seed=9, rounds=1)
    assert rec.record(*message(ev.SessionStarted(config=cfg)), 1)
    # seq 2 never comes (lost on the bus); 3 is recorded; 4-5 wait in the inbox at the exit, shed; 6 ends the session
    assert rec.record(*message(ev.RoundStarted(round=0, faces=[i // 2 for i in range(18)]), seq=3), 3)
    rec.inbox.put(*message(ev.CardRevealed(round=0, turn=0, card=0, face=0, pick=0), seq=4))
    rec.inbox.put(*message(ev.CardRevealed(round=0, turn=0, card=1, face=0, pick=1), seq=5))
    rec.inbox.put(*message(ev.SessionEnded(reason="interrupted", detail="SIGTERM"), seq=6))
    assert rec.close(stopped_by="SIGTERM", deadline=Deadline(0.0)) is None
    log = read_log(tmp_path / "r1.mcap")
    assert [r.event.seq for r in log.events if r.event.source == "game"] == [1, 3, 6]
    end = log.metadata["pairplay.recorder.end"]
    [shed] = [r.event for r in log.events if isinstance(r.event, ev.MessageRejected)]
    assert end["unrecorded_at_exit"] == "2" and shed.reason.startswith("2 messages ") and "still queued" in shed.reason
    lost = log.metadata["pairplay.recovered"]
    assert (lost["lost_count"], lost["shed_count"], lost["bus"], lost["shed"]) == ("1", "2", "true", "true"), lost
    assert json.loads(lost["lost"]) == ["game seq 2 (1 event)", "game seqs 4-5 (2 events shed at the exit)"]
    assert json.loads(lost["damaged"]) == ["lost on the bus: game seq 2 (1 event)",
                                           "shed at the exit: game seqs 4-5 (2 events shed at the exit)"]
    assert "lost on the bus that no refill gave back and events its recorder shed at the exit" in log.missing
    result = verify_recording(log.path)
    assert not result.ok and "shed at the exit" in result.error and "game seq 2 (1 event) lost" in result.error



def test_a_hole_a_full_inbox_left_mid_session_is_said_once_as_shed_not_also_as_lost_on_the_bus(tmp_path):
    """A flood mid-session fills the recorder's inbox: what it sheds is counted (its MessageRejected "inbox full"
    count). The hole that left in the file, when no refill gave it back, was also said to be lost on the bus and
    counted again (`lost_count`), as the exit's shedding was before SHED_AT_EXIT. Now it is said under its cause
    (SHED_LIVE, `flood` "true"), counted once in `shed_count`; the bus's hole beside it is still the bus's."""
    import json

    from pairplay.services.verify import verify_recording

    rec = flooding(tmp_path / "r1.mcap")
    # seq 2 never comes (lost on the bus); 3 is taken; 4 and 5 are shed (the inbox holds 3); 6 ends the session
    assert rec.inbox.put(*message(ev.RoundStarted(round=0, faces=[i // 2 for i in range(18)]), seq=3))
    assert not rec.inbox.put(*message(ev.CardRevealed(round=0, turn=0, card=0, face=0, pick=0), seq=4))
    assert not rec.inbox.put(*message(ev.CardRevealed(round=0, turn=0, card=1, face=0, pick=1), seq=5))
    rec.step(0)
    assert rec.record(*message(ev.SessionEnded(), seq=6), 6)
    assert rec.close() is None
    log = read_log(tmp_path / "r1.mcap")
    assert [r.event.seq for r in log.events if r.event.source == "game"] == [1, 3, 6]
    [shed] = [r.event for r in log.events if isinstance(r.event, ev.MessageRejected)]
    assert shed.reason.startswith("2 messages ") and "inbox full" in shed.reason, shed.reason
    lost = log.metadata["pairplay.recovered"]
    assert (lost["lost_count"], lost["shed_count"], lost["bus"], lost["flood"]) == ("1", "2", "true", "true"), lost
    assert "shed" not in lost  # (not at the exit)
    assert json.loads(lost["lost"]) == ["game seq 2 (1 event)", "game seqs 4-5 (2 events shed by its full inbox)"]
    assert json.loads(lost["damaged"]) == ["lost on the bus: game seq 2 (1 event)",
                                           "shed by its full inbox: game seqs 4-5 (2 events shed by its full inbox)"]
    assert log.missing.startswith("events lost on the bus that no refill gave back and events its recorder's full "
                                  "inbox shed in a flood (no refill gave them back) (r1.mcap): "), log.missing
    result = verify_recording(log.path)
    assert not result.ok and "shed by its full inbox" in result.error and "game seq 2 (1 event) lost" in result.error
