"""A pause or resume that crosses a touch in flight verifies in every order a recorder can file it.

The console's SessionPaused / SessionResumed (source "experimenter") and the board's touches reach the
recorder by different links: it files them as they reach it, not as the game took them. Verify fed them
in file order, so a pause filed on the wrong side of a touch made the touch DIFFER although the live game
was right (docs/study.md "Running game", open until the game marked where it took each control: its
ControlTaken). The recordings here are made by the real game and learner logics in their Drivers, the
order the game took its inputs, and written with the recorder's own writer in an order a recorder could
have filed them: an input moved to the other side of a touch.
"""

from __future__ import annotations

from pairplay.replay.writer import EventLogWriter
from pairplay.schemas import events as ev
from pairplay.schemas.events import encode_event
from pairplay.schemas.keys import event_key
from pairplay.services.verify import verify_recording

from test_game_human import Recorded

S = "t"  # Table's session


class Live(Recorded):
    """A person's game as it ran (the game and the learner wired together, every event in the order it
    was published, each input before what it caused); `take(name, source, event, at_s)` is an input,
    named, and says what the game published for it."""

    def __init__(self, announce: bool = False):
        super().__init__(announce=announce)
        self.named: dict[str, object] = {}

    def take(self, name: str, source: str, event, at_s: float) -> list[str]:
        before = len(self.log)
        self.named[name] = self.send(source, event, at_s)
        return [type(x).__name__ for x in self.log[before + 1:] if x.source == "game"]


def played() -> Live:
    """Turn 1: the first touch, a pause (a second pause refused: already paused), a touch refused as
    paused, the resume, the touch again; turn 2 likewise; then the experimenter aborts."""
    live = Live()
    first = 0
    miss = next(c for c in range(18) if live.faces[c] != live.faces[first])
    t = 100.0
    assert live.take("touch1", "board", ev.CardPicked(round=0, turn=0, card=first), t)[0] == "CardRevealed"
    assert live.take("pause1", "experimenter", ev.SessionPaused(reason="a question"), t + 1) != ["MessageRejected"]
    assert live.take("pause1b", "experimenter", ev.SessionPaused(reason="clicked twice"), t + 1.1) == \
        ["MessageRejected"]  # already paused: refused, no mark
    assert live.take("refused1", "board", ev.CardPicked(round=0, turn=0, card=miss), t + 2) == ["PickRejected"]
    assert live.take("resume1", "experimenter", ev.SessionResumed(), t + 5) != ["MessageRejected"]
    assert live.take("touch2", "board", ev.CardPicked(round=0, turn=0, card=miss), t + 6)[0] == "CardRevealed"
    t += 10
    second = next(c for c in range(18) if c not in (first, miss) and live.faces[c] != live.faces[first])
    assert live.take("touch3", "board", ev.CardPicked(round=0, turn=1, card=second), t)[0] == "CardRevealed"
    assert live.take("pause2", "experimenter", ev.SessionPaused(reason="the robot froze"), t + 1) != ["MessageRejected"]
    assert live.take("resume2", "experimenter", ev.SessionResumed(), t + 3) != ["MessageRejected"]
    assert live.take("resume2b", "experimenter", ev.SessionResumed(), t + 3.1) == ["MessageRejected"]
    assert live.take("abort", "experimenter", ev.SessionAborted(reason="the participant had to leave"), t + 4) == \
        ["SessionEnded"]
    return live


def filed(live: Live, path, *moves: tuple[str, str, bool]):
    """Write the live session with each input `moved` filed just before (or after) input `beside`, as a
    recorder that took them in that order would (every other event where it was); returns the path."""
    events = list(live.log)
    for moved, beside, after in moves:
        e = live.named[moved]
        events.remove(e)
        at = events.index(live.named[beside]) + (1 if after else 0)
        if after:  # after the touch and what the game published for it (a recorder sees the answer first too)
            while at < len(events) and events[at].source in ("game", "learner"):
                at += 1
        events.insert(at, e)
    writer = EventLogWriter(path)
    for i, x in enumerate(events):
        writer.write(event_key(S, x.source, type(x).__name__), encode_event(x), log_time_ns=10**18 + i * 10**6,
                     sequence=x.seq)
    writer.close()
    return path


def verdict(path) -> tuple[bool, list[str]]:
    v = verify_recording(path)
    return v.ok, [m for c in v.checks for m in c.mismatches]


def test_the_game_marks_where_it_took_each_pause_and_resume_and_the_session_as_it_took_it_verifies(tmp_path):
    live = played()
    marks = [(e.control, e.control_source, e.control_seq) for e in live.log if type(e).__name__ == "ControlTaken"]
    assert marks == [(type(live.named[n]).__name__, "experimenter", live.named[n].seq)
                     for n in ("pause1", "resume1", "pause2", "resume2")]  # the refused ones have none
    took = [type(e).__name__ for e in live.log]
    assert took[took.index("ControlTaken") - 1] == "SessionPaused"  # published as it took the pause
    assert verdict(filed(live, tmp_path / "live.mcap")) == (True, [])


def test_a_pause_filed_before_a_touch_the_game_took_first_verifies(tmp_path):
    """The game took touch 1 (turned the card), then the pause; the recorder filed the pause first. Verify
    paused the game before the touch, refused it and said CardRevealed DIFFERS."""
    assert verdict(filed(played(), tmp_path / "p.mcap", ("pause1", "touch1", False))) == (True, [])
    assert verdict(filed(played(), tmp_path / "p2.mcap", ("pause2", "touch3", False))) == (True, [])


def test_a_touch_refused_as_paused_filed_before_the_pause_verifies(tmp_path):
    """The game took the pause, then refused a touch ("the session is paused"); the recorder filed the touch
    first. Verify turned the card over and said PickRejected DIFFERS."""
    assert verdict(filed(played(), tmp_path / "t.mcap", ("refused1", "pause1", False))) == (True, [])


def test_a_resume_filed_after_a_touch_the_game_took_after_resuming_verifies(tmp_path):
    """The game resumed, then took touch 2; the recorder filed the resume after it. Verify refused the touch
    as paused and said CardRevealed DIFFERS."""
    assert verdict(filed(played(), tmp_path / "r.mcap", ("resume1", "touch2", True))) == (True, [])


def test_a_refused_control_is_not_taken_wherever_it_is_filed(tmp_path):
    """The game took touch 1, then the pause, then refused a second pause (already paused); the recorder
    filed both pauses before the touch. Fed where the file holds it, the second pause would be taken
    (the first waits for its place after the touch): the game paused before the touch."""
    path = filed(played(), tmp_path / "pb.mcap", ("pause1", "touch1", False), ("pause1b", "touch1", False))
    assert verdict(path) == (True, [])


def test_replay_verify_says_pass_for_a_pause_filed_on_the_wrong_side(tmp_path, capsys):
    from pairplay.cli.main import main

    path = filed(played(), tmp_path / "cli.mcap", ("pause1", "touch1", False))
    assert main(["replay", str(path), "--verify"]) == 0
    out = capsys.readouterr().out
    assert "DIFFERS" not in out and out.splitlines()[-1].startswith("verify: PASS up to where the session stopped")


def test_a_game_restarted_over_such_a_log_is_where_the_live_game_was():
    """A restart re-feeds the recorded log the same way (services/node.py `resume`): the game that took touch 1
    and then the pause, its log holding the pause first, comes back with the card up and paused; one that
    crashed between taking its first pause and publishing the mark publishes the mark it owes."""
    from pairplay.services.game import GameLogic
    from pairplay.services.node import Driver

    live = Live()
    live.take("touch1", "board", ev.CardPicked(round=0, turn=0, card=0), 100.0)
    live.take("pause1", "experimenter", ev.SessionPaused(reason="a question"), 101.0)
    log = list(live.log)
    log.remove(live.named["pause1"])
    log.insert(log.index(live.named["touch1"]), live.named["pause1"])
    restarted = Driver(GameLogic(live.config), S, clock=lambda: 10**18)
    assert restarted.resume(log) == [] and restarted.mismatches == []
    assert restarted.logic.paused and restarted.logic.first == 0
    unmarked = [e for e in live.log if type(e).__name__ != "ControlTaken"]
    restarted = Driver(GameLogic(live.config), S, clock=lambda: 10**18)
    owed = restarted.resume(unmarked)
    assert [type(e).__name__ for e in owed] == ["ControlTaken"] and restarted.logic.paused


def test_a_refused_pause_after_the_last_touch_filed_before_it_verifies_in_a_game_that_took_no_pause(tmp_path):
    """A game that took no pause holds no mark; a pause that came after its last touch (refused: the game had
    ended) was filed before that touch. Read as a log from before the marks, the pause was fed there, the
    last touch refused as paused: DIFFERS. The game's ServiceStarted now says it marks what it takes, so a
    control without a mark in its log was not taken, mark or none elsewhere."""
    def whole_round(announce: bool) -> Live:
        live = Live(announce=announce)
        pairs: dict[int, list[int]] = {}
        for card, face in enumerate(live.faces):
            pairs.setdefault(face, []).append(card)
        t = 100.0
        for turn, (a, b) in enumerate(pairs.values()):
            live.take("first", "board", ev.CardPicked(round=0, turn=turn, card=a), t)
            live.take("last", "board", ev.CardPicked(round=0, turn=turn, card=b), t + 1)
            t += 2
        assert any(type(e).__name__ == "SessionEnded" for e in live.log)
        assert "ControlTaken" not in live.take("late", "experimenter", ev.SessionPaused(reason="too late"), t)
        return live

    assert verdict(filed(whole_round(True), tmp_path / "late.mcap", ("late", "last", False))) == (True, [])
    # a log from before the marks (no ServiceStarted naming them) is fed in file order, as it always was
    ok, mismatches = verdict(filed(whole_round(False), tmp_path / "old.mcap", ("late", "last", False)))
    assert not ok and any("the session is paused" in m for m in mismatches), mismatches
