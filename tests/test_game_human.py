"""The game and the learner with a person's inputs (no network): the page's clock for the
ignore rule, stale wrong-suggestion presses, the eye tracker's fixations."""

from __future__ import annotations

from pairplay.schemas import events as ev
from pairplay.schemas.envelope import stamped
from pairplay.schemas.events import encode_event
from pairplay.schemas.keys import event_key
from pairplay.schemas.session import SessionConfig
from pairplay.services.game import GameLogic
from pairplay.services.learner import LearnerLogic
from pairplay.services.node import Driver
from pairplay.services.verify import verify_events


class Table:
    """A game and a learner wired together; `send(source, event, at_s)` is an input."""

    def __init__(self, announce: bool = False, **fields):
        """`announce`: the game's ServiceStarted first, naming the inputs it marks, as services/runner.py's."""
        fields = {"observed_source": "first-pick", "ignore_rule": "time", "ignore_clock": "page"} | fields
        self.config = SessionConfig(session="t", participant="human:p1", seed=1, rounds=1, **fields)
        self.game = Driver(GameLogic(self.config), "t", lambda: 0)
        self.learner = Driver(LearnerLogic(), "t", lambda: 0)
        self.log: list = []
        self.seq: dict[str, int] = {}
        if announce:
            self.publish(self.game._stamp([ev.ServiceStarted(service="game", marks=sorted(GameLogic.PLACED))]))
        self.publish(self.game.start())
        self.faces = next(e for e in self.log if isinstance(e, ev.RoundStarted)).faces

    def publish(self, events):
        for e in events:
            self.log.append(e)
            self.publish(self.learner.receive(event_key("t", e.source, type(e).__name__), encode_event(e)))

    def send(self, source, event, at_s):
        self.seq[source] = self.seq.get(source, 0) + 1
        e = stamped(event, session="t", source=source, seq=self.seq[source], time_ns=int(at_s * 1e9))
        self.publish(self.game.receive(event_key("t", source, type(event).__name__), encode_event(e)))

    def of(self, cls):
        return [e for e in self.log if isinstance(e, cls)]

    def miss(self):
        return 0, next(c for c in range(18) if self.faces[c] != self.faces[0])


class Recorded(Table):
    """A Table whose log holds the inputs too, each before what it caused, as a recorder holds them;
    `send` returns the input as stamped."""

    def send(self, source, event, at_s):
        self.seq[source] = self.seq.get(source, 0) + 1
        e = stamped(event, session="t", source=source, seq=self.seq[source], time_ns=int(at_s * 1e9))
        self.log.append(e)
        self.publish(self.game.receive(event_key("t", source, type(event).__name__), encode_event(e)))
        return e


def test_the_ignore_rule_times_the_picks_on_the_page_clock_and_records_both():
    t = Table()
    a, b = t.miss()
    t.send("board", ev.CardPicked(round=0, turn=0, card=a, page_time_ms=5000.0), 10.0)
    t.send("board", ev.CardPicked(round=0, turn=0, card=b, page_time_ms=5400.0), 12.0)  # page 0.4 s, server 2 s
    turn = t.of(ev.TurnResolved)[0]
    assert turn.page_interval_ms == 400.0 and turn.interval_ms == 2000.0 and turn.ignored_by_time
    assert t.of(ev.RewardGiven)[0].learned is False
    server = Table(ignore_clock="server")
    server.send("board", ev.CardPicked(round=0, turn=0, card=a, page_time_ms=5000.0), 10.0)
    server.send("board", ev.CardPicked(round=0, turn=0, card=b, page_time_ms=5400.0), 12.0)
    assert not server.of(ev.TurnResolved)[0].ignored_by_time and server.of(ev.RewardGiven)[0].learned


def test_a_second_press_for_the_same_suggestion_is_stale():
    t = Table()
    a, b = t.miss()
    t.send("board", ev.CardPicked(round=0, turn=0, card=a), 10.0)
    t.send("board", ev.WrongSuggestionPressed(round=0, turn=0, attempt=0), 10.5)
    t.send("board", ev.WrongSuggestionPressed(round=0, turn=0, attempt=0), 10.6)  # a double tap
    assert [r.attempt for r in t.of(ev.SuggestionRequested)] == [0, 1]
    assert [r.attempt for r in t.of(ev.SuggestionMade)] == [0, 1]
    assert [(r.attempt, r.reward) for r in t.of(ev.RewardGiven)] == [(0, -3.0)]  # -3 once, then a new suggestion
    assert "stale" in t.of(ev.MessageRejected)[0].reason


def test_the_eye_tracker_gives_the_observed_card_and_a_silent_one_stalls_nothing():
    t = Table(observed_source="gaze")
    a, b = t.miss()
    t.send("tracker", ev.GazeFixated(card=7), 9.0)  # before the first pick: not about this turn
    t.send("board", ev.CardPicked(round=0, turn=0, card=a), 10.0)
    assert not t.of(ev.SuggestionRequested)
    t.send("tracker", ev.GazeFixated(card=a), 10.2)  # the first card itself
    t.send("tracker", ev.GazeFixated(card=99), 10.3)  # off the board: refused
    t.send("tracker", ev.GazeFixated(card=12), 10.4)
    assert [(o.card, o.observed_source) for o in t.of(ev.CardObserved)] == [(12, "gaze")]
    assert t.of(ev.SuggestionRequested)[0].observed == 12
    t.send("board", ev.CardPicked(round=0, turn=0, card=b), 12.0)
    # turn 1: the tracker says nothing; the second pick still ends the turn, without a suggestion
    c, d = [x for x in range(18) if x not in (a, b)][:2]
    t.send("board", ev.CardPicked(round=0, turn=1, card=c), 20.0)
    t.send("board", ev.CardPicked(round=0, turn=1, card=d), 22.0)
    assert [r.turn for r in t.of(ev.TurnResolved)] == [0, 1] and len(t.of(ev.SuggestionMade)) == 1
    assert [m.reason for m in t.of(ev.MessageRejected)][0].startswith("malformed payload")  # the schema refuses an off-board card where it enters (issue 12)
    # a fixation that came in before the first pick it follows (another link) still counts
    t.send("tracker", ev.GazeFixated(card=15), 30.5)
    e, f = [x for x in range(18) if x not in (a, b, c, d) and x != 15][:2]
    t.send("board", ev.CardPicked(round=0, turn=2, card=e), 30.0)
    assert t.of(ev.CardObserved)[-1].card == 15 and t.of(ev.SuggestionRequested)[-1].turn == 2


def test_only_the_tracker_may_report_gaze():
    t = Table(observed_source="gaze")
    t.send("board", ev.GazeFixated(card=3), 1.0)
    assert "published only by tracker" in t.of(ev.MessageRejected)[0].reason  # schemas/trust.py


def test_inputs_for_another_round_are_refused_with_rounds_counted_from_1_and_old_wordings_still_verify():
    """Before: `pick for round 1 turn 3, but the game is at round 0 turn 0`, the indices, a round behind the
    board's `Round 1`. A recorded PickRejected is compared by verify (and a restart's resume) with the
    recomputed one, so recordings made before keep their wording and must still verify: same numbers,
    either wording; a changed number still fails."""
    import msgspec

    t = Recorded()
    t.send("board", ev.CardPicked(round=1, turn=3, card=0), 1.0)
    t.send("board", ev.WrongSuggestionPressed(round=0, turn=2, attempt=0), 1.5)
    t.send("board", ev.CardObserved(round=2, turn=0, card=1, observed_source="intended"), 1.7)
    [picked] = t.of(ev.PickRejected)
    assert picked.reason == "pick for round 2, turn 4, but the game is in round 1, turn 1"
    assert [m.reason for m in t.of(ev.MessageRejected)] == [
        "WrongSuggestionPressed for round 1, turn 3, but the game is in round 1, turn 1",
        "CardObserved for round 3, turn 1, but the game is in round 1, turn 1"]
    a, b = t.miss()
    t.send("board", ev.CardPicked(round=0, turn=0, card=a), 2.0)
    t.send("board", ev.CardPicked(round=0, turn=0, card=b), 4.0)  # the game goes on, as before the refusals
    assert len(t.of(ev.TurnResolved)) == 1
    assert verify_events(t.log).ok

    def worded(reason):
        return [msgspec.structs.replace(e, reason=reason) if isinstance(e, ev.PickRejected) else e for e in t.log]
    assert verify_events(worded("pick for round 1 turn 3, but the game is at round 0 turn 0")).ok  # as recorded before
    for tampered in ("pick for round 1 turn 3, but the game is at round 0 turn 1",
                     "pick for round 2, turn 4, but the game is in round 2, turn 1"):
        assert not verify_events(worded(tampered)).ok, tampered
