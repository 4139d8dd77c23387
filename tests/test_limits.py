"""Events built from outside input stay within the bus's limits (schemas/trust.py: MAX_PAYLOAD, clip).

A listener sheds a payload over MAX_PAYLOAD unread: an event of ours that copied a hostile message's
text past it was lost to every listener, and the recording had a hole no refill filled (trial28 F21:
a forged 60,000-character source made the game's refusal 120 KB; verify FAIL, rebuild refused)."""

import threading

import pytest

from pairplay.replay.reader import read_log
from pairplay.schemas import events as ev
from pairplay.schemas.envelope import stamped
from pairplay.schemas.keys import alive_key, event_key
from pairplay.schemas.session import SessionConfig
from pairplay.schemas.trust import MAX_PAYLOAD
from pairplay.services.guard import Guard, Refusals
from pairplay.services.verify import verify_recording

from busutil import connector, session_in_thread, wait_until

SESSION = "lim1"
HUGE = 60_000  # characters: the forged message itself is under MAX_PAYLOAD, its refusal quoted it twice


def forged_pick(source: str = "p" * HUGE, session: str = SESSION) -> tuple[str, bytes]:
    """A valid-looking CardPicked on the participant's key claiming a 60,000-character source."""
    e = stamped(ev.CardPicked(round=0, turn=0, card=3), session=session, source=source, seq=1, time_ns=1)
    payload = ev.encode_event(e)
    assert len(payload) <= MAX_PAYLOAD  # taken off the bus and read: its refusal is what must fit
    return event_key(SESSION, "participant", "CardPicked"), payload


def test_a_refusal_quoting_a_huge_source_fits_the_bus_and_says_what_was_cut():
    key, payload = forged_pick()
    verdict = Guard(SESSION, own="game").check(key, payload)
    assert verdict.reason and len(verdict.reason) > HUGE  # the guard's reason quotes the source
    refusals = Refusals()
    out = refusals.refuse(1, verdict.reason, key, verdict.event.source, verdict.event.seq, payload)
    assert refusals.recorded and len(out) == 1
    rejected = stamped(out[0], session=SESSION, source="game", seq=2, time_ns=2)
    assert len(ev.encode_event(rejected)) <= MAX_PAYLOAD
    assert "more characters cut]" in rejected.reason and "more characters cut]" in rejected.offending_source
    # the worst text: control characters, 6 bytes each in JSON, in the reason, the key and the source
    worst = "\x01" * HUGE
    out = Refusals().refuse(1, worst, worst, worst, 1, worst.encode())
    assert len(ev.encode_event(stamped(out[0], session=SESSION, source="game", seq=2, time_ns=2))) <= MAX_PAYLOAD


def test_a_forged_message_with_a_huge_source_leaves_the_recording_whole(tmp_path):
    path = tmp_path / f"{SESSION}.mcap"
    config = SessionConfig(session=SESSION, participant="sim:wasim", persona="wasim", seed=2, rounds=2)
    # the game waits for the intruder's token, so the forgery lands while every service listens
    runner, box = session_in_thread(config, path, wait_also=("intruder",))
    with connector(box["bus"]) as intruder:
        everyone = {alive_key(SESSION, s) for s in ("recorder", "learner", "participant", "game")}
        assert wait_until(lambda: everyone <= intruder.alive_now(alive_key(SESSION, "*")), timeout_s=60)
        intruder.put(*forged_pick())
        intruder.alive(alive_key(SESSION, "intruder"))
        runner.join(120)
    assert not runner.is_alive()
    recorded = read_log(path)
    refusals = [r.event for r in recorded.events if isinstance(r.event, ev.MessageRejected)
                and r.event.key.endswith("participant/CardPicked")]
    # every listener's refusal was recorded (the game's too: it was the one lost), none shed as too large
    assert {"game", "recorder"} <= {r.source for r in refusals}
    assert all("more characters cut]" in r.offending_source for r in refusals)
    assert not [r.event for r in recorded.events if isinstance(r.event, ev.MessageRejected) and "larger than" in r.event.reason]
    assert verify_recording(path).verdict == "verify: PASS"


def test_an_abort_off_the_bus_with_a_huge_reason_ends_the_session_within_the_bus_limit():
    # a SessionAborted that fits the bus, its reason copied as the game's SessionEnded detail, with more around it
    from pairplay.services.game import GameLogic
    from pairplay.services.node import Driver
    game = Driver(GameLogic(SessionConfig(session=SESSION, participant="sim:wasim", persona="wasim", seed=2, rounds=2)),
                  SESSION, clock=lambda: 5)
    game.start()
    abort = stamped(ev.SessionAborted(reason=""), session=SESSION, source="experimenter", seq=1, time_ns=1)
    abort = stamped(ev.SessionAborted(reason="R" * (MAX_PAYLOAD - len(ev.encode_event(abort)))), session=SESSION,
                    source="experimenter", seq=1, time_ns=1)
    payload = ev.encode_event(abort)
    assert len(payload) == MAX_PAYLOAD  # as large as the bus takes
    out = game.receive(event_key(SESSION, "experimenter", "SessionAborted"), payload)
    end = next(e for e in out if isinstance(e, ev.SessionEnded))
    assert end.reason == "aborted" and "more characters cut]" in end.detail
    assert len(ev.encode_event(end)) <= MAX_PAYLOAD


def test_the_console_refuses_an_over_long_pause_or_abort_reason_in_one_line(tmp_path):
    from test_console_api import STUDY, call
    from pairplay.replay.studydata import StudyData
    from pairplay.services.bus import Bus, BusOptions
    from pairplay.services.console.server import ConsoleServer
    from pairplay.services.protocol import StudyRunner
    data = StudyData.create(tmp_path / "study", STUDY)
    with Bus(BusOptions()) as bus:
        runner = StudyRunner(data, bus)
        server = ConsoleServer(runner).start()
        try:
            for action in ("pause", "abort"):
                status, answer = call(f"{server.url}/api/console/control/{action}?token={server.token}",
                                      {"reason": "R" * 65_400})
                assert status == 400 and answer["error"] == "a reason is at most 1,000 characters, this one has 65,400"
            assert not runner.live.paused
        finally:
            server.close()


def test_a_pause_before_the_game_has_begun_is_refused_not_shown_as_taken(tmp_path):
    """trial35 F1: a console Pause in a game's first moment, before the game was on the bus, was answered ok and
    shown paused while the game played every round; its Resume was refused "not paused". Refused until the game's
    first RoundStarted is seen."""
    from test_console_api import STUDY
    from pairplay.replay.studydata import StudyData
    from pairplay.services.bus import Bus, BusOptions
    from pairplay.services.protocol import StudyRunner
    from pairplay.replay.studydata import StudyDataError
    data = StudyData.create(tmp_path / "study", STUDY)
    with Bus(BusOptions()) as bus:
        runner = StudyRunner(data, bus)
        runner.live.state, runner.live.session = "playing", "s"  # a game just started: no RoundStarted seen yet
        with pytest.raises(StudyDataError, match="the game is starting"):
            runner.pause()
        assert not runner.live.paused
        runner.live.see(ev.RoundStarted(round=0, faces=[0] * 18))
        assert runner.live.started


def test_the_combiners_answer_to_a_request_of_huge_paths_fits_the_bus(tmp_path):
    from pairplay.services.combiner import CombinerLogic
    # two paths of 30,000 characters: the request fits the bus; the answer echoes both and its error quotes one
    request = ev.CombineRequested(request_id="r1", policies=["../" + "x" * 30_000, "y" * 30_000])
    assert len(ev.encode_event(stamped(request, session=SESSION, source="console", seq=1, time_ns=1))) <= MAX_PAYLOAD
    [answer] = CombinerLogic(tmp_path).handle(request)
    assert not answer.ok and answer.error
    assert len(ev.encode_event(stamped(answer, session=SESSION, source="combiner", seq=1, time_ns=1))) <= MAX_PAYLOAD


def test_a_session_whose_learner_never_answers_says_so_once(tmp_path, monkeypatch, caplog):
    # trial28 F19: a liveliness token with no learner behind it started a session that waited for ever without a word
    from pairplay.services import unanswered
    monkeypatch.setattr(unanswered, "SAY_AFTER_S", 0.5)
    config = SessionConfig(session="lim2", participant="sim:wasim", persona="wasim", seed=2, rounds=2)
    stop = threading.Event()
    caplog.set_level("WARNING", logger="pairplay.session")
    runner, box = session_in_thread(config, tmp_path / "lim2.mcap", external=("learner",), stop=stop)
    try:
        with connector(box["bus"]) as impostor:
            impostor.alive(alive_key("lim2", "learner"))  # a token, and no learner
            said = lambda: [r.getMessage() for r in caplog.records if "is the learner running?" in r.getMessage()]
            assert wait_until(said, timeout_s=60)
            assert said()[0].startswith("waiting ") and "for the learner's SuggestionMade to SuggestionRequested seq " in said()[0]
            stop.set()
            runner.join(60)
    finally:
        stop.set()
        runner.join(60)
    assert not runner.is_alive()
    assert len(said()) == 1  # once for the request, not every 0.1 s


def test_questionnaire_answers_too_large_for_the_bus_are_refused_in_one_line(tmp_path):
    from test_console_api import STUDY
    from pairplay.replay.studydata import StudyData, StudyDataError
    from pairplay.services.bus import Bus, BusOptions
    from pairplay.services.protocol import StudyRunner
    import pytest
    study = tmp_path / "study.toml"  # the pilot study, its text items allowing 20,000 characters each
    study.write_text(STUDY.read_text().replace('kind = "text"\n', 'kind = "text"\nmax_chars = 20000\n'))
    data = StudyData.create(tmp_path / "study", study)
    pid = data.register("phase1")
    with Bus(BusOptions()) as bus:
        runner = StudyRunner(data, bus)
        runner._game_bus = bus  # the state of a game that just ended and awaits its questionnaire
        runner.live.session, runner.live.participant, runner.live.phase = "lim3", pid, "phase1"
        runner.live.state, runner.live.questionnaire_token = "questionnaire", "t0k"
        name, items = runner.questions_for(pid, "phase1")
        answers = {i.id: "\u20ac" * 20_000 if i.kind == "text" else (i.options[0] if i.kind == "choice" else "3")
                   for i in items}  # 40,000 euro signs: 120,000 bytes
        with pytest.raises(StudyDataError, match="over the bus's limit of 65,536 bytes: shorten it"):
            runner.answer_questionnaire("lim3", "t0k", answers)
        shorter = {k: v[:100] for k, v in answers.items()}  # the page may send them again, shortened
        assert runner.answer_questionnaire("lim3", "t0k", shorter).answers == shorter


def test_a_message_shed_as_too_large_is_counted_in_words_not_with_a_literal_N():
    from pairplay.services.bus import Inbox
    inbox = Inbox(max_payload=10)
    assert not inbox.put(event_key(SESSION, "board", "CardPicked"), b"x" * 11)
    refusals = Refusals()
    refusals.shed(inbox.take_shed())
    [count] = refusals.tick(1, force=True)
    assert count.reason == ("1 message refused and not recorded one by one (limit 20/s): "
                            "shed unread (larger than the bus's payload limit)")


def test_a_counted_refusals_reason_is_whole_or_cut_at_a_word_with_its_marker():
    # trial33 L: "shed unread (suggestion not reported, ... (lost on the bus" was cut at 100 characters
    from collections import Counter

    from pairplay.services.recorder import UNREPORTED
    refusals = Refusals()
    refusals.shed(Counter({("robot", UNREPORTED): 5}))
    [count] = refusals.tick(1, force=True)
    assert count.reason.endswith(f"shed unread ({UNREPORTED})")
    refusals.shed(Counter({("robot", "word " * 60): 1}))
    [count] = refusals.tick(2, force=True)
    said = count.reason.split(": ", 1)[1]
    assert said.endswith("more characters cut]") and "word... [" in said  # at a word, not "wo"


def test_clip_cuts_at_a_word_and_counts_what_it_cut():
    from pairplay.schemas.trust import clip
    assert clip("alpha beta gamma", 12) == "alpha beta... [6 more characters cut]"
    assert clip("x" * 20, 8) == "xxxxxxxx... [12 more characters cut]"  # one long word: at the limit
