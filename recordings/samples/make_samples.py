"""Make the committed sample recordings (run once per recording format; the files are then frozen).

Rule: samples are evidence that later versions still read old recordings
(tests/test_replay_samples.py decodes and verifies them); never regenerate them
to make a test pass. Each format gets its own three files, named with
FORMAT (format 1: pairplay 0.1.0, `sim-ashley.mcap` ...; format 2: times as
{sec, nsec}, stream derivation 2, SessionEnded with how far it got, the
recorder's own log and publish times, `sim-ashley-fmt2.mcap` ...):
- sim-ashley.mcap: a real bus session (`pairplay session`), simulated persona
  Ashley, seed 7, 4 rounds, with an intruder's bad input rejected on the way;
- human-board.mcap: a human-study session (first-pick observation, the 1.5 s
  ignore rule, a wrong-suggestion press) played by a scripted touch screen
  through the real game and learner logics, written by the recorder's writer;
- catalogue.mcap: one event of every type of the catalogue, RobotActed,
  PolicyCombined and QuestionnaireAnswered included.

    .venv/bin/python recordings/samples/make_samples.py recordings/samples

The recorder's times are its own: log time is when the recorder took a message,
from one clock, monotonic in the file (the human sample's board times stay in
the events' envelopes); publish time is the log time.
"""

from __future__ import annotations

import sys
import threading
from pathlib import Path

from pairplay import __version__
from pairplay.core.rng import STREAMS_VERSION
from pairplay.replay.writer import EventLogWriter
from pairplay.schemas import events as ev
from pairplay.schemas.envelope import Nanos
from pairplay.schemas.envelope import stamped
from pairplay.schemas.events import encode_event
from pairplay.schemas.keys import alive_key, event_key
from pairplay.schemas.robot import RobotActed
from pairplay.schemas.session import SessionConfig
from pairplay.services.bus import Bus, BusOptions
from pairplay.services.game import GameLogic
from pairplay.services.learner import LearnerLogic
from pairplay.services.node import Driver
from pairplay.services.session import run_session


FORMAT = "fmt2"


def sim_sample(out: Path) -> None:
    config = SessionConfig(session="sample-sim-ashley", participant="sim:ashley", persona="ashley", seed=7, rounds=4,
                           software_version=__version__, streams=STREAMS_VERSION)
    ready, box = threading.Event(), {}

    def on_bus(bus):
        box["bus"] = bus
        ready.set()

    t = threading.Thread(target=lambda: run_session(config, out / f"sim-ashley-{FORMAT}.mcap", on_bus=on_bus,
                                                    wait_also=("intruder",)))
    t.start()
    ready.wait()
    with Bus(BusOptions(listen=[], connect=box["bus"].locators())) as intruder:
        s = config.session
        want = {alive_key(s, n) for n in ("recorder", "learner", "participant", "game")}
        while not want <= intruder.alive_now(alive_key(s, "*")):
            pass
        intruder.put(event_key(s, "participant", "CardPicked"), b"{not json")
        bad_pick = stamped(ev.CardPicked(round=0, turn=0, card=42), session=s, source="board", seq=1, time_ns=1)
        intruder.put(event_key(s, "board", "CardPicked"), encode_event(bad_pick))
        intruder.alive(alive_key(s, "intruder"))
        t.join()


def scripted_session(config: SessionConfig, path: Path):
    """A game and a learner logic wired to one MCAP writer (no bus), the recorder's times from one
    clock: returns the writer, the game's Driver and `inject(source, event, at_s)`, which records
    an input (its envelope time `at_s`) and everything it causes."""
    clock = iter(range(10**18, 10**19, 10**6)).__next__
    recorder_clock = iter(range(2 * 10**18, 3 * 10**18, 10**5)).__next__  # the recorder's own, one clock
    game, learner = Driver(GameLogic(config), config.session, clock), Driver(LearnerLogic(), config.session, clock)
    writer = EventLogWriter(path)
    writer.add_metadata("pairplay.session", {"session": config.session, "seed": str(config.seed),
                                             "software_version": __version__, "streams": str(config.streams)})

    def record(events):
        for e in events:
            key = event_key(e.session, e.source, type(e).__name__)
            writer.write(key, encode_event(e), log_time_ns=recorder_clock(), sequence=e.seq)
            if e.source == "game":
                record(learner.receive(key, encode_event(e)))

    seqs: dict[str, int] = {}

    def inject(source, event, at_s):
        seqs[source] = seqs.get(source, 0) + 1
        e = stamped(event, session=config.session, source=source, seq=seqs[source], time_ns=int(at_s * 1e9))
        key = event_key(config.session, source, type(event).__name__)
        writer.write(key, encode_event(e), log_time_ns=recorder_clock(), sequence=e.seq)
        record(game.receive(key, encode_event(e)))

    record(game.start())
    return writer, game, inject


def scripted_turn(faces: list[int], matched: int, turn: int) -> tuple[int, int, list[int], int]:
    """The scripted touch screen's cards: the first covered card, then a miss on even turns
    (while one is possible) and its partner on odd ones."""
    covered = [c for c in range(18) if not matched >> c & 1]
    first = covered[0]
    partner = next(c for c in covered if c != first and faces[c] == faces[first])
    others = [c for c in covered if c not in (first, partner)]
    return first, partner, others, partner if turn % 2 or not others else others[0]


def human_sample(out: Path) -> None:
    config = SessionConfig(session="sample-human-board", participant="human:p01", seed=3, rounds=1,
                           observed_source="first-pick", ignore_rule="time", software_version=__version__,
                           streams=STREAMS_VERSION)
    writer, game, inject = scripted_session(config, out / f"human-board-{FORMAT}.mcap")
    faces = list(game.logic.board.faces)
    t_s, matched, turn = 100.0, 0, 0
    while not game.logic.done:
        first, partner, others, second = scripted_turn(faces, matched, turn)
        inject("board", ev.CardPicked(round=0, turn=turn, card=first), t_s)
        if turn == 1:
            inject("board", ev.WrongSuggestionPressed(round=0, turn=turn), t_s + 1.0)
        inject("board", ev.CardPicked(round=0, turn=turn, card=second), t_s + (0.8 if turn == 2 else 2.5))  # turn 2: too fast
        if faces[first] == faces[second]:
            matched |= (1 << first) | (1 << second)
        turn += 1
        t_s += 10
    writer.close()


def gaze_sample(out: Path) -> None:
    """A person whose observed card comes from an eye tracker (GazeFixated), picks timed on the
    board page's clock, a stale second wrong-suggestion press, a turn without a fixation."""
    config = SessionConfig(session="sample-human-gaze", participant="human:p02", seed=5, rounds=1,
                           observed_source="gaze", ignore_rule="time", ignore_clock="page",
                           software_version=__version__, streams=STREAMS_VERSION)
    writer, game, press = scripted_session(config, out / f"human-gaze-{FORMAT}.mcap")
    faces = list(game.logic.board.faces)
    t_s, matched, turn = 100.0, 0, 0
    while not game.logic.done:
        first, partner, others, second = scripted_turn(faces, matched, turn)
        page_ms = t_s * 1000 + 0.25  # the page's clock runs 250 us off the server's
        press("board", ev.CardPicked(round=0, turn=turn, card=first, page_time_ms=page_ms), t_s)
        if turn != 3:  # turn 3: the tracker saw nothing, the turn goes without a suggestion
            press("tracker", ev.GazeFixated(card=others[-1] if others else partner, duration_ms=240.0), t_s + 0.4)
        if turn == 1:
            press("board", ev.WrongSuggestionPressed(round=0, turn=turn, attempt=0, page_time_ms=page_ms + 900), t_s + 0.9)
            press("board", ev.WrongSuggestionPressed(round=0, turn=turn, attempt=0, page_time_ms=page_ms + 950), t_s + 0.95)
        gap = 0.8 if turn == 2 else 2.5  # turn 2: too fast
        press("board", ev.CardPicked(round=0, turn=turn, card=second, page_time_ms=page_ms + gap * 1000), t_s + gap + 0.1)
        if faces[first] == faces[second]:
            matched |= (1 << first) | (1 << second)
        turn += 1
        t_s += 10
    writer.close()


def console_sample(out: Path) -> None:
    """The experimenter's console on a person's game: a pause (a touch refused meanwhile), a resume,
    and an abort with a suggestion still open (SessionPaused, SessionResumed, SessionAborted)."""
    config = SessionConfig(session="sample-console", participant="human:p01", seed=5, rounds=2,
                           observed_source="first-pick", ignore_rule="time", software_version=__version__,
                           streams=STREAMS_VERSION)
    writer, game, inject = scripted_session(config, out / f"console-{FORMAT}.mcap")
    faces = list(game.logic.board.faces)
    t_s, matched = 100.0, 0
    for turn in range(4):
        first, partner, others, second = scripted_turn(faces, matched, turn)
        inject("board", ev.CardPicked(round=0, turn=turn, card=first), t_s)
        if turn == 1:
            inject("experimenter", ev.SessionPaused(reason="the participant asked a question"), t_s + 1)
            inject("board", ev.CardPicked(round=0, turn=turn, card=second), t_s + 2)  # refused: paused
            inject("experimenter", ev.SessionResumed(), t_s + 5)
        if turn == 3:  # the last suggestion is open when the experimenter stops the game
            inject("experimenter", ev.SessionAborted(reason="the participant had to leave"), t_s + 1)
            break
        inject("board", ev.CardPicked(round=0, turn=turn, card=second), t_s + 6)
        if faces[first] == faces[second]:
            matched |= (1 << first) | (1 << second)
        t_s += 10
    writer.close()


def catalogue_sample(out: Path) -> None:
    s = "sample-catalogue"
    cfg = SessionConfig(session=s, participant="sim:deaf", persona="deaf", seed=1, rounds=1,
                        software_version=__version__, streams=STREAMS_VERSION)
    events = [
        ev.ServiceStarted(service="game", version=__version__), ev.SessionStarted(config=cfg),
        ev.RoundStarted(round=0, faces=[i // 2 for i in range(18)]), ev.CardPicked(round=0, turn=0, card=0),
        ev.CardRevealed(round=0, turn=0, card=0, face=0, pick=0, pick_seq=1),
        ev.PickRejected(round=0, turn=0, card=0, reason="card 0 is already face up", pick_source="participant"),
        ev.CardObserved(round=0, turn=0, card=1, observed_source="intended"),
        ev.SuggestionRequested(round=0, turn=0, attempt=0, state=12, observed=1, match=1, covered_mask=262142, first=0),
        ev.SuggestionMade(round=0, turn=0, attempt=0, state=12, action=35, chosen_by="explore", epsilon=0.9, alpha=0.5,
                          psi=0.0, observed=1, target=1, action_name="x"),
        RobotActed(round=0, turn=0, attempt=0, action=35, backend="virtual", outcome="done", commands=["say"],
                   received_ns=10**18 + 123_456_789, sent_ns=10**18 + 123_456_999, acked_ns=10**18 + 223_456_789,
                   done_ns=10**18 + 923_456_789),
        ev.SuggestionPerceived(round=0, turn=0, attempt=0, considered=True, consistent=True, candidate_size=1,
                               candidate_mask=2, second=1),
        ev.WrongSuggestionPressed(round=0, turn=0),
        ev.TurnResolved(round=0, turn=0, first=0, second=1, matched=True, round_over=False, interval_ms=2000.0),
        ev.RewardGiven(round=0, turn=0, attempt=0, state=12, action=35, reward=2.0, learned=True, reason="match"),
        ev.QUpdated(round=0, turn=0, attempt=0, state=12, action=35, alpha=0.5, reward=2.0, q_before=0.0, q_after=1.0),
        ev.LSPIUpdated(round=0, turn=0, attempt=0, state=12, action=35, reward=2.0, samples=1, improved=False,
                       q_before=0.0, q_after=0.0),
        ev.RoundEnded(round=0, turns=9, matches=9),
        ev.CombineRequested(request_id="r1", recordings=["a.mcap"], seed=1),
        ev.PolicyCombined(request_id="r1", inputs=["a.mcap"], actions=[35] * 24, decided_by=["equal; equal"] * 24),
        ev.QuestionnaireAnswered(questionnaire="phase1", answers={"q1": "4"}),
        ev.ControlTaken(control="SessionPaused", control_source="experimenter", control_seq=1),
        ev.MessageRejected(reason="malformed payload", key=f"pairplay/{s}/participant/CardPicked", excerpt="{not"),
        ev.RecordingGap(earlier_file=f"{s}.mcap", copied=20, last_copied_ns=Nanos(1_796_000_000_123_456_789),
                        resumed_ns=Nanos(1_796_000_001_123_456_789),
                        refilled=1, refilled_from=["game"]),
        ev.SessionEnded(reason="completed", rounds_played=1),
    ]
    writer = EventLogWriter(out / f"catalogue-{FORMAT}.mcap")
    writer.add_metadata("pairplay.session", {"session": s, "participant": cfg.participant, "persona": cfg.persona,
                                             "seed": str(cfg.seed), "software_version": __version__,
                                             "streams": str(cfg.streams), "note": "hand-made: one event of each type"})
    seqs: dict[str, int] = {}
    for i, e in enumerate(events):
        source = {"CardPicked": "participant", "CardObserved": "participant", "SuggestionPerceived": "participant",
                  "WrongSuggestionPressed": "board", "QuestionnaireAnswered": "board", "SuggestionMade": "learner",
                  "RewardGiven": "learner", "QUpdated": "learner", "LSPIUpdated": "learner", "RobotActed": "robot",
                  "CombineRequested": "console", "PolicyCombined": "combiner", "MessageRejected": "recorder",
                  "RecordingGap": "recorder"}.get(type(e).__name__, "game")
        seqs[source] = seqs.get(source, 0) + 1
        e = stamped(e, session=s, source=source, seq=seqs[source], time_ns=1_796_000_000_123_456_789 + i * 1_000_003)
        writer.write(event_key(s, source, type(e).__name__), encode_event(e), log_time_ns=e.time_ns, sequence=e.seq)
    writer.close()


if __name__ == "__main__":
    out = Path(sys.argv[1] if len(sys.argv) > 1 else "recordings/samples")
    if sys.argv[2:3] == ["--gaze"]:  # the eye-tracker sample alone (added after the others were made)
        gaze_sample(out)
        sys.exit(0)
    if sys.argv[2:3] == ["--console"]:  # the console's sample alone (added after the others were made)
        console_sample(out)
        sys.exit(0)
    if sys.argv[2:3] == ["--catalogue"]:  # the catalogue alone (remade when an event type is added)
        catalogue_sample(out)
        sys.exit(0)
    sim_sample(out)
    human_sample(out)
    gaze_sample(out)
    console_sample(out)
    catalogue_sample(out)
    for p in sorted(out.glob(f"*-{FORMAT}.mcap")):
        print(p, p.stat().st_size)
