"""Answers to a source's question given by a session that is not the source (trial34 O; services/answers.py).
Under an access control that restricted only puts, a client with the robot's certificate answered the recorder's
catch-up question `_query/learner/sent` with a forged learner event: the recorder wrote it (verify PASS), the
learner's own answer skipped without a word; its empty answer made a restarted recorder refuse its own live
session. Whatever the bus lets through, two answers that differ for one event are taken from neither and recorded,
and an empty answer never outvotes one that holds the events. Real parts: the game's Node on a real bus, a real
Recorder, the forger a Zenoh session of its own on that bus."""

from __future__ import annotations

import threading

import pytest

from pairplay.replay.reader import read_log
from pairplay.schemas import events as ev
from pairplay.schemas.envelope import stamped
from pairplay.schemas.events import decode_event, encode_event
from pairplay.schemas.keys import event_key, query_key
from pairplay.schemas.session import SessionConfig
from pairplay.services.bus import Bus, Deadline
from pairplay.services.game import GameLogic
from pairplay.services.recorder import Recorder, same_live_session
from pairplay.services.runner import SENT_QUERY, Node

import msgspec

from busutil import connector, listener, wait_until


def forged_start(s: str) -> bytes:
    """The game's seq 1 as a forger makes it: a ServiceStarted of another service name and version."""
    return encode_event(stamped(ev.ServiceStarted(service="game FORGED", version="6.6.6"), session=s, source="game",
                                seq=1, time_ns=1))


def forging(bus: Bus, forger: Bus, s: str, items: list[tuple[str, bytes]], source: str = "game") -> str:
    """`forger` answers `source`'s question with `items`, as `source`; returns its ZenohId once its answer
    reaches `bus` (a queryable takes a moment to be known)."""
    forger.queryable(query_key(s, source, SENT_QUERY),
                     lambda q: Bus.answer(q, [msgspec.msgpack.encode((source, items))]))
    zid = str(forger.session.zid())
    assert wait_until(lambda: zid in {r for r, _ in bus.query_replies(query_key(s, source, SENT_QUERY), 0.5)}, 30)
    return zid


def refilled(bus: Bus, s: str, path) -> tuple[list[ev.MessageRejected], object]:
    """A recorder restarted on `path` (its refill asks every source), stepped until its RecordingGap is written,
    then closed: (its rejections that say a forged answer, its file read back)."""
    second = Recorder(bus, s, path, restart=True)
    second.start()
    try:
        assert wait_until(lambda: second.step(0.05) and False or
                          any(k.endswith("/RecordingGap") for k, _ in second.kept), 120)
        said = [r for r in rejections(second.kept) if "forged answer" in r.reason]
    finally:
        second.close(deadline=Deadline(5.0))
    return said, read_log(second.path)


@pytest.fixture
def game_on_bus():
    """A game Node on a real bus, started (its first events went to nobody), running until the test ends."""
    def start(bus: Bus, s: str) -> Node:
        config = SessionConfig(session=s, participant="human:t", seed=1, rounds=3, observed_source="first-pick",
                               ignore_rule="time")
        game = Node(bus, GameLogic(config), s, resume=False)
        game.start()
        game.run_in_thread(stop)
        started.append(game)
        return game
    stop = threading.Event()
    started: list[Node] = []
    yield start
    stop.set()
    for game in started:
        game.thread.join(10)
        game.close()


def pick(bus: Bus, s: str) -> None:
    """The board's first pick: the game answers it past its seq 3 (its first events went to nobody)."""
    picked = stamped(ev.CardPicked(round=0, turn=0, card=0), session=s, source="board", seq=1, time_ns=1)
    bus.put(event_key(s, "board", "CardPicked"), encode_event(picked))


def recording(bus: Bus, s: str, out) -> Recorder:
    """A Recorder of `s` into folder `out`, started; then a pick, and the recorder stepped until it holds the
    session (the game's head caught up: `_catch_up`). The caller closes it."""
    recorder = Recorder(bus, s, out / f"{s}.mcap")
    recorder.start()
    pick(bus, s)
    if not wait_until(lambda: recorder.step(0.05) and False or recorder.holds_session, 60):
        recorder.close(deadline=Deadline(5.0))
        raise AssertionError([k for k, _ in recorder.kept])
    return recorder


def rejections(kept) -> list[ev.MessageRejected]:
    return [e for e in (decode_event(p) for k, p in kept if k.endswith("/MessageRejected"))
            if isinstance(e, ev.MessageRejected)]


def test_two_answers_that_differ_for_a_head_event_are_taken_from_neither_and_recorded(tmp_path, game_on_bus):
    """The recorder's catch-up (`_catch_up`) asks the game for its first events; the game and a forger both answer
    seq 1, differently. Before: whichever came first was written, the other skipped silently (the forger's first:
    a forged event in the file, verify PASS)."""
    s = "forgedhead"
    with listener() as bus, connector(bus) as forger:
        game = game_on_bus(bus, s)
        forger_zid = forging(bus, forger, s, [(event_key(s, "game", "ServiceStarted"), forged_start(s))])
        recorder = recording(bus, s, tmp_path)
        try:
            # the game gone from the question, a refill asks again: the forger alone answers the disputed seq 1,
            # which is not taken either (before, a lone answer after the dispute was: trial34 O, rerun)
            bus.release(game._sent_query)
            assert wait_until(lambda: str(bus.session.zid()) not in
                              {r for r, _ in bus.query_replies(query_key(s, "game", SENT_QUERY), 0.5)}, 30)
            recorder.refill(since_ns=recorder.clock())
            said = [r for r in rejections(recorder.kept) if "forged answer" in r.reason]
        finally:
            recorder.close(deadline=Deadline(5.0))
    assert len(said) == 1, said
    assert said[0].offending_source == "game" and said[0].offending_seq == 1
    assert forger_zid in said[0].reason and str(bus.session.zid()) in said[0].reason, said[0].reason
    log = read_log(tmp_path / f"{s}.mcap")
    assert not [r for r in log.events if isinstance(r.event, ev.ServiceStarted) and r.event.version == "6.6.6"]
    game_seqs = {r.event.seq for r in log.events if r.event.source == "game"}
    assert 1 not in game_seqs and {2, 3} <= game_seqs  # neither seq 1 taken: a hole the file says
    assert any(isinstance(r.event, ev.SessionStarted) for r in log.events)


@pytest.mark.parametrize("forged", ["empty", "other bytes"])
def test_a_forger_s_answer_does_not_make_a_restarted_recorder_refuse_its_own_live_session(tmp_path, game_on_bus,
                                                                                          forged):
    """`same_live_session` (a restarted recorder: is the session on the bus the one its file recorded?): the game
    answers with the file's bytes, a forger with nothing (trial34 O addendum: before, its empty answer decided
    "no", and the recorder refused its own live session) or with other bytes (one of the two is not the game:
    that answer counts as none; the game's own is then asked again, and with no other source it is "no")."""
    s = "forgedsame"
    with listener() as bus, connector(bus) as forger:
        game_on_bus(bus, s)
        recorder = recording(bus, s, tmp_path)
        recorder.close(deadline=Deadline(5.0))
        assert same_live_session(bus, s, tmp_path / f"{s}.mcap")  # the game alone: the same session
        forging(bus, forger, s, [] if forged == "empty" else [(event_key(s, "game", "ServiceStarted"),
                                                                forged_start(s))])
        same = same_live_session(bus, s, tmp_path / f"{s}.mcap", timeout_s=1.0)
    assert same is (forged == "empty")


def test_two_answers_that_differ_in_a_restarted_recorder_s_refill_are_taken_from_neither(tmp_path):
    """The restart's refill (`Recorder.refill`) asks every source for what it sent after the earlier file's last
    event; the game and a forger both answer its seq 4, differently. Before: the first one came was taken (a
    forged range would have been folded by rebuild), the other skipped silently."""
    from test_recorder_restart import _a_recorded_game_not_yet_running

    s = "forgedrefill"
    path = tmp_path / f"{s}.mcap"
    stop = threading.Event()
    with listener() as bus, connector(bus) as forger:
        game = _a_recorded_game_not_yet_running(bus, s, path)  # seqs 1-3 recorded, that recorder closed
        game.run_in_thread(stop)
        try:
            sent = []
            bus.subscribe(f"pairplay/{s}/game/*", lambda k, p: sent.append(decode_event(p).seq))
            pick(bus, s)  # the game publishes its seq 4 on
            assert wait_until(lambda: 4 in sent, 60), sent
            forger_zid = forging(bus, forger, s, [(event_key(s, "game", "ServiceStarted"),
                                                   encode_event(stamped(ev.ServiceStarted(service="game FORGED"),
                                                                        session=s, source="game", seq=4,
                                                                        time_ns=1)))])
            said, log = refilled(bus, s, path)
        finally:
            stop.set()
            game.thread.join(10)
            game.close()
    assert len(said) == 1 and (said[0].offending_source, said[0].offending_seq) == ("game", 4), said
    assert forger_zid in said[0].reason, said[0].reason
    assert not [r for r in log.events if isinstance(r.event, ev.ServiceStarted) and "FORGED" in r.event.service]
    game_seqs = {r.event.seq for r in log.events if r.event.source == "game"}
    assert 4 not in game_seqs and {1, 2, 3, 5} <= game_seqs, game_seqs  # seq 4: neither taken, a hole said


def test_a_log_answered_differently_by_two_sessions_is_taken_from_neither(tmp_path, game_on_bus, caplog):
    """A joining service folds the recorder's log (`fetch_log`, `_query/recorder/log`): a second session answering
    as the recorder with its own log was merged into it, its events folded as the session's. Now two sessions'
    logs that differ are no log, said in a warning naming both."""
    from pairplay.services.runner import LOG_QUERY, fetch_log

    s = "forgedlog"
    with listener() as bus, connector(bus) as forger:
        game_on_bus(bus, s)
        recorder = recording(bus, s, tmp_path)
        try:
            serving = threading.Event()
            helper = threading.Thread(target=lambda: [recorder.step(0.05) for _ in iter(serving.is_set, True)],
                                      daemon=True)
            helper.start()  # the recorder answers its queries from its own step
            try:
                assert {1, 2, 3} <= {e.seq for e in fetch_log(bus, s) if e.source == "game"}  # the recorder alone
                forger.queryable(query_key(s, "recorder", LOG_QUERY), lambda q: Bus.answer(
                    q, [msgspec.msgpack.encode((0, [(event_key(s, "game", "ServiceStarted"), forged_start(s))]))]))
                zid = str(forger.session.zid())
                assert wait_until(lambda: zid in {r for r, _ in bus.query_replies(query_key(s, "recorder", LOG_QUERY),
                                                                                   0.5)}, 30)
                with caplog.at_level("WARNING", logger="pairplay.answers"):
                    got = fetch_log(bus, s)
            finally:
                serving.set()
                helper.join(10)
        finally:
            recorder.close(deadline=Deadline(5.0))
    assert got == []
    assert zid in caplog.text and "not the recorder" in caplog.text, caplog.text


def test_an_answer_for_another_source_than_the_one_it_was_sent_as_is_never_taken(tmp_path):
    """trial35 O1: under the fixed example's access control the robot host may answer only its own question, and
    it answered that (`_query/robot/sent`) with the learner's events, seqs its learner had not sent yet: alone,
    the restart's refill wrote 26 forged QUpdated (q_after 99). An answer's event is taken only for the source its
    reply was sent as (the reply's key, which access control limits per host): refused and recorded."""
    from test_recorder_restart import _a_recorded_game_not_yet_running

    s = "foreignsrc"
    path = tmp_path / f"{s}.mcap"
    stop = threading.Event()
    ahead = encode_event(stamped(ev.ServiceStarted(service="game FORGED"), session=s, source="game", seq=40,
                                 time_ns=1))
    with listener() as bus, connector(bus) as forger:
        game = _a_recorded_game_not_yet_running(bus, s, path)  # seqs 1-3 recorded, that recorder closed
        game.run_in_thread(stop)
        try:
            # its own question: the ACL lets it answer this
            forging(bus, forger, s, [(event_key(s, "game", "ServiceStarted"), ahead)], source="robot")
            said, log = refilled(bus, s, path)
        finally:
            stop.set()
            game.thread.join(10)
            game.close()
    assert said and "answered as 'robot' with 'game''s seq 40" in said[0].reason, said
    assert not [r for r in log.events if isinstance(r.event, ev.ServiceStarted) and "FORGED" in r.event.service]
