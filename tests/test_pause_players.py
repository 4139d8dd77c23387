"""A player logic paused and resumed by the experimenter goes on (services/pausehold.py), on a real loopback bus.

Before: a persona's pilot game (`protocol serve --pilot`) paused and resumed from the console never went on: its
pick, refused "the session is paused", was never made again and the game stayed "playing" for good (trial34 F); the
simulated participant service refused its own refused pick and waited the same way. Whatever the moment of the
pause, something of the player's is refused or held: the game always waits for the player, or for the learner whose
suggestion the player answers.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

from pairplay.replay.studydata import StudyData
from pairplay.schemas import events as ev
from pairplay.schemas.envelope import stamped
from pairplay.schemas.keys import event_key
from pairplay.schemas.session import SessionConfig
from pairplay.services.bus import Bus, BusOptions
from pairplay.services.protocol import StudyRunner
from pairplay.services.scripted import ScriptedPlayer
from pairplay.services.session import run_session
from pairplay.services.verify import verify_recording

STUDY = Path(__file__).parent / "data" / "pilot-study.toml"
ENOUGH_S = 60.0  # a bound on a hang, never a measure: a game of 2 short rounds ends in a second or two


def until(condition, what: str) -> None:
    deadline = time.monotonic() + ENOUGH_S
    while not condition():
        assert time.monotonic() < deadline, f"never: {what}"
        time.sleep(0.01)


def refused_or_held(seen: list, player: str, logic) -> bool:
    """The pause took something of the player's: an input refused for it, or (with the hold) one held."""
    refused = any(isinstance(e, ev.PickRejected) and e.pick_source == player and e.reason.startswith("the session is "
                  "paused") or isinstance(e, ev.MessageRejected) and e.offending_source == player for e in seen)
    hold = getattr(logic, "hold", None)
    return refused or bool(hold and hold.held)


def test_a_scripted_pilot_paused_and_resumed_from_the_console_plays_to_its_end(tmp_path):
    data = StudyData.create(tmp_path / "s", STUDY)
    pid = data.register("phase1")
    seen: list = []
    result: dict = {}
    with Bus(BusOptions()) as bus:
        runner = StudyRunner(data, bus)
        name, items = runner.questions_for(pid, "phase1")
        player = ScriptedPlayer("ashley", questions=items, questionnaire=name)
        game = threading.Thread(target=lambda: result.setdefault("game", runner.run_game(
            pid, "phase1", 0, player, on_event=seen.append)))
        game.start()
        try:
            until(lambda: sum(isinstance(e, ev.CardRevealed) for e in seen) >= 3, "3 picks")
            runner.pause("a question")  # what the console's Pause calls
            until(lambda: any(isinstance(e, ev.ControlTaken) for e in seen), "the pause taken")
            until(lambda: refused_or_held(seen, "board", player), "a touch refused or held while paused")
            runner.resume()
            game.join(ENOUGH_S)
            assert not game.is_alive(), f"the game never went on after the resume: {runner.live.picks} picks"
        finally:
            if game.is_alive():
                runner.abort("the test ends it")
                game.join(ENOUGH_S)
    ended = result["game"].ended
    assert (ended.outcome, ended.rounds_played) == ("completed", 2)
    assert [e.control for e in seen if isinstance(e, ev.ControlTaken)] == ["SessionPaused", "SessionResumed"]
    assert verify_recording(data.folder / result["game"].recording).ok


def test_the_simulated_participant_service_paused_and_resumed_plays_to_its_end(tmp_path):
    config = SessionConfig(session="paused-sim", participant="sim:ashley", persona="ashley", seed=3, rounds=30,
                           observed_source="intended")
    seen: list = []
    out: dict = {}
    with Bus(BusOptions()) as bus:
        bus.subscribe("pairplay/paused-sim/**", lambda _k, p: seen.append(ev.decode_event(p)))
        stop = threading.Event()
        nodes: dict = {}
        session = threading.Thread(target=lambda: out.setdefault("path", run_session(
            config, tmp_path / "paused-sim.mcap", bus=bus, stop=stop, nodes_out=nodes)))
        session.start()

        def control(e, seq: int) -> None:
            bus.put(event_key("paused-sim", "experimenter", type(e).__name__),
                    ev.encode_event(stamped(e, session="paused-sim", source="experimenter", seq=seq,
                                            time_ns=time.time_ns())))
        try:
            until(lambda: sum(isinstance(e, ev.CardRevealed) for e in seen) >= 6, "6 picks")
            control(ev.SessionPaused(reason="a question"), 1)
            until(lambda: any(isinstance(e, ev.ControlTaken) for e in seen), "the pause taken")
            until(lambda: refused_or_held(seen, "participant", getattr(nodes.get("participant"), "logic", None)),
                  "an input refused or held while paused")
            control(ev.SessionResumed(), 2)
            session.join(ENOUGH_S)
            assert not session.is_alive(), "the session never went on after the resume"
        finally:
            stop.set()
            session.join(ENOUGH_S)
    ends = [e for e in seen if isinstance(e, ev.SessionEnded)]
    assert [(e.reason, e.rounds_played) for e in ends] == [("completed", 30)]
    assert verify_recording(out["path"]).ok


def test_a_press_or_an_observed_card_in_flight_at_the_pause_is_made_again_and_one_answered_is_not():
    """The game refuses a paused press or observed card with a MessageRejected, which no player reads: the hold
    sends again, at the resume, the input the game had not answered by then (a SuggestionRequested of the
    attempt it asks), and never one it answered."""
    from pairplay.services.pausehold import PauseHold

    def control(tag: str) -> ev.ControlTaken:
        return ev.ControlTaken(control=tag, control_source="experimenter", control_seq=1)

    def asked(attempt: int) -> ev.SuggestionRequested:
        return ev.SuggestionRequested(round=0, turn=0, attempt=attempt, state=0, observed=1, match=2,
                                      covered_mask=0b111, first=0)

    for sent, answer in ((ev.WrongSuggestionPressed(round=0, turn=0, attempt=0), asked(1)),
                         (ev.CardObserved(round=0, turn=0, card=1, observed_source="intended"), asked(0))):
        hold = PauseHold("board")
        assert hold.send([sent]) == [sent]
        hold.saw(control("SessionPaused"))
        assert hold.saw(control("SessionResumed")) == [sent]  # refused while paused: made again
        hold.send([sent])
        hold.saw(answer)  # taken before the pause
        hold.saw(control("SessionPaused"))
        later = ev.CardPicked(round=0, turn=0, card=2)
        assert hold.send([later]) == []  # held while paused
        assert hold.saw(control("SessionResumed")) == [later]


def test_the_hold_reads_any_event_of_the_game_with_an_input_open():
    """An event with no turn (RoundStarted, SessionStarted) read while an input is open is no answer, and no
    error (the logic's Node would record an internal error and drop the event)."""
    from pairplay.services.pausehold import PauseHold

    hold = PauseHold("participant")
    pick = ev.CardPicked(round=0, turn=0, card=3)
    hold.send([pick])
    for e in (ev.RoundStarted(round=1, faces=[i // 2 for i in range(18)]), ev.SessionStarted(config=SessionConfig(
            session="s", participant="sim:ashley", persona="ashley", seed=1, rounds=2))):
        assert hold.saw(e) == [] and hold.open is pick
