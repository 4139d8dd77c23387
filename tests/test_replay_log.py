"""The event log: what is written reads back, a cut file keeps everything
before the last flush, `recover` completes it, and the fold rebuilds Q."""

import json

import jsonschema
import numpy as np
import pytest

from pairplay.errors import InputError, OutputError
from mcap.reader import make_reader

from pairplay.core.learning import q_update
from pairplay.replay.fold import fold_events
from pairplay.replay.reader import EventDecoderFactory, read_any_log, read_log
from pairplay.replay.recover import recover
from pairplay.replay.writer import EventLogWriter
from pairplay.schemas import keys
from pairplay.schemas.envelope import stamped
from pairplay.schemas.events import CardPicked, QUpdated, SessionStarted, encode_event
from pairplay.schemas.session import SessionConfig

SESSION = "s1"


def picks(n):
    for i in range(n):
        e = stamped(CardPicked(round=0, turn=i, card=i % 18), session=SESSION, source="participant",
                    seq=i + 1, time_ns=1_000 + i)
        yield keys.event_key(SESSION, "participant", "CardPicked"), encode_event(e), e


def write(path, n, flush_every=None, close=True, started=False):
    """`n` picks written at `path`; `started`: after the session's SessionStarted (a file recover completes: one
    holding no session is refused by every verb, recover too)."""
    w = EventLogWriter(path)
    w.add_metadata("pairplay.session", {"seed": "7"})
    if started:
        e = stamped(SessionStarted(config=SessionConfig(session=SESSION, participant="sim:ashley", persona="ashley",
                                                        seed=7, rounds=3)), session=SESSION, source="game", seq=1,
                    time_ns=999)
        w.write(keys.event_key(SESSION, "game", "SessionStarted"), encode_event(e), log_time_ns=999, sequence=1)
    for i, (key, payload, e) in enumerate(picks(n)):
        w.write(key, payload, log_time_ns=e.time_ns, sequence=e.seq)
        if flush_every and (i + 1) % flush_every == 0:
            w.flush(e.time_ns)
    if close:
        w.close()
    return w


def test_written_events_read_back_with_metadata_and_validate(tmp_path):
    path = tmp_path / "a.mcap"
    write(path, 50)
    log = read_log(path)
    assert not log.truncated and not log.bad
    assert [r.event.turn for r in log.events] == list(range(50))
    assert log.metadata["pairplay.session"] == {"seed": "7"}
    # the mcap package's standard reader with our decoder, and each message against its channel's schema
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[EventDecoderFactory()])
        decoded = list(reader.iter_decoded_messages())
    assert len(decoded) == 50
    for schema, channel, message, event in decoded:
        assert channel.topic == "pairplay/s1/participant/CardPicked"
        jsonschema.validate(json.loads(message.data), json.loads(schema.data))
        assert event.card == (message.sequence - 1) % 18


def test_flush_interval_is_time_based():
    import io
    w = EventLogWriter(io.BytesIO(), flush_interval_ns=100)
    assert w.due_in_ns(0) is None  # nothing to flush
    key, payload, e = next(picks(1))
    w.write(key, payload, log_time_ns=1000)
    assert not w.maybe_flush(1050)
    assert w.maybe_flush(1100)
    assert w.due_in_ns(1200) is None


@pytest.mark.parametrize("cut", [0.3, 0.6, 0.95])
def test_a_cut_file_reads_up_to_the_last_flush_and_recovers(tmp_path, cut):
    path = tmp_path / "full.mcap"
    write(path, 400, flush_every=100, close=False, started=True)  # killed: never closed, last 0 unflushed
    data = path.read_bytes()
    cut_path = tmp_path / "cut.mcap"
    cut_path.write_bytes(data[: int(len(data) * cut)])
    log = read_log(cut_path)
    assert log.truncated and log.error
    n = len(log.events)
    turns = [r.event.turn for r in log.events[1:]]
    assert (n - 1) % 100 == 0 and turns == list(range(n - 1))  # its start, then whole chunks, in order
    done = recover(cut_path)
    assert done.truncated and done.messages == n
    fixed = read_log(done.output)
    assert not fixed.truncated and len(fixed.events) == n
    assert fixed.metadata["pairplay.recovered"]["messages"] == str(n)
    with open(done.output, "rb") as f:
        assert sum(1 for _ in make_reader(f).iter_messages()) == n


def test_unflushed_writer_file_holds_every_flushed_chunk(tmp_path):
    path = tmp_path / "live.mcap"
    w = write(path, 250, flush_every=100, close=False)
    w._stream.flush()
    assert len(read_log(path).events) == 200  # the open chunk (50) is what a SIGKILL loses


def test_recover_refuses_to_overwrite_its_input(tmp_path):
    path = tmp_path / "a.mcap"
    write(path, 3)
    with pytest.raises(OutputError):
        recover(path, path)


def test_a_garbage_file_is_reported_by_the_any_file_reader_and_refused_by_read_log(tmp_path):
    """read_any_log (recover's, a server's read-back) says what the file is not; read_log, the public API's,
    refuses it naming the file, as every verb does (tests/test_python_api_edges.py)."""
    path = tmp_path / "junk.mcap"
    path.write_bytes(b"not an mcap file at all")
    log = read_any_log(path)
    assert log.truncated and not log.events
    with pytest.raises(InputError, match="not a recording: not an MCAP file"):
        read_log(path)


def test_fold_rebuilds_q_with_the_learners_update_and_flags_gaps():
    rng = np.random.default_rng(0)
    q = np.zeros((24, 88))
    events = []
    for i in range(300):
        s, a, r, alpha = int(rng.integers(24)), int(rng.integers(88)), float(rng.normal()), float(rng.random())
        before = q[s, a]
        q[s, a] = q_update(q[s, a], r, alpha)
        events.append(QUpdated(round=0, turn=i, attempt=0, state=s, action=a, alpha=alpha, reward=r,
                               q_before=float(before), q_after=float(q[s, a])))
    folded = fold_events(events)
    assert np.array_equal(folded.q, q) and folded.q_mismatches == 0
    first = QUpdated(round=0, turn=0, attempt=0, state=3, action=4, alpha=0.5, reward=1.0, q_before=0.0, q_after=0.5)
    second = QUpdated(round=0, turn=1, attempt=0, state=3, action=4, alpha=0.5, reward=1.0, q_before=0.5, q_after=0.75)
    assert fold_events([first, second]).q_mismatches == 0
    assert fold_events([second]).q_mismatches == 1  # a lost update shows


def test_reading_only_what_the_fold_reads_gives_the_same_fold_and_keeps_bad_messages(tmp_path):
    """read_log(only=READS), rebuild's read: events the fold only counts are checked by their
    envelope and counted, not decoded; the fold is the same; a message whose envelope does not
    check out is still decoded wholly and kept as a BadMessage, never counted as an event."""
    from pairplay.replay.fold import READS

    path = tmp_path / "r.mcap"
    w = EventLogWriter(path)
    pick_key = keys.event_key(SESSION, "participant", "CardPicked")
    q_key = keys.event_key(SESSION, "learner", "QUpdated")
    for i, (key, payload, e) in enumerate(picks(30)):
        w.write(key, payload, log_time_ns=e.time_ns, sequence=e.seq)
        q = stamped(QUpdated(round=0, turn=i, attempt=0, state=1, action=i % 88, reward=1.0, alpha=0.5,
                             q_before=0.0, q_after=0.5),
                    session=SESSION, source="learner", seq=i + 1, time_ns=e.time_ns)
        w.write(q_key, encode_event(q), log_time_ns=e.time_ns, sequence=i + 1)
    w.write(pick_key, b'{"type":"QUpdated"', log_time_ns=5_000, sequence=40)  # not JSON: bad
    w.write(pick_key, b'{"type":"RoundEnded","round":0,"turns":1,"matches":1,"session":"s1","source":"game",'
                      b'"seq":1,"time_ns":1}', log_time_ns=5_001, sequence=41)  # another event on its channel
    w.close()
    whole, some = read_log(path), read_log(path, only=READS)
    assert some.skipped == {"CardPicked": 30} and not whole.skipped
    # the RoundEnded on a CardPicked channel is not what its key names: a bad message too, whole or not
    # (reader.disagreement: trial28 F2, where it was read as an event)
    assert {type(r.event).__name__ for r in some.events} == {"QUpdated"}
    assert len(some.bad) == len(whole.bad) == 2 and "it names type 'CardPicked'" in some.bad[1].reason
    a = fold_events(r.event for r in whole.events)
    b = fold_events(r.event for r in some.events).count(some.skipped)
    assert (a.q == b.q).all() and a.counts == b.counts and a.events == b.events == 60
    assert a.turns_per_round() == b.turns_per_round()


def test_a_round_a_session_stopped_in_is_no_row_of_the_curve_nor_a_round_played():
    """Cut (or stopped) part way into round 2: the fold counted round 2 (its rewards made it a round)
    as a round of 0 turns and 0 picks: the curve ended in a 'perfect' 0, the policy said 2 rounds, the
    mean picks fell. Whole rounds only; round 2's updates still count in the Q-table."""
    from loopback_session import loopback_events
    from pairplay.replay.rebuild import curve_rows, rebuild_events
    from pairplay.schemas.session import SessionConfig

    events = loopback_events(SessionConfig(session="cut2", participant="sim:blind", persona="blind", seed=3,
                                           rounds=3))
    first_end = next(i for i, e in enumerate(events) if type(e).__name__ == "RoundEnded")
    later = next(i for i, e in enumerate(events) if i > first_end and type(e).__name__ == "QUpdated")
    cut = events[:later + 3]
    rebuilt = rebuild_events(cut, "cut2.mcap", truncated=True)
    fold = rebuilt.fold
    assert fold.whole_rounds() == [0] and len(fold.picks_per_round()) == 1 and fold.picks_per_round()[0] > 0
    assert [row["round"] for row in curve_rows(fold)] == [0]
    assert rebuilt.policy.rounds == 1 and "stops after 1 round" in rebuilt.partial and "1 rounds" not in rebuilt.partial
    assert sum(fold.visits) == sum(type(e).__name__ == "QUpdated" for e in cut)  # round 2's updates kept
