"""Verify checks what was recorded up to where the session stopped, whatever the moment (a new user's trial).

A session stopped by SIGINT/SIGTERM (or the experimenter, or a lost service)
ends with the SessionEnded its shell made the game publish (services/session.py
`end_game`); the services then stop, so what they would have derived from
the last inputs is missing. Verify used to compare that end with a game
recomputed to the last input and said DIFFERS at the interrupted round (a
false FAIL), while a file cut at a random byte verified. Here a session on a
perfect in-process bus (tests/loopback_session.py) is stopped after every k-th
delivery, before the first pick, between a pick and its suggestion, between
rounds: every stop verifies, says how far, and one altered event before the
stop still fails.
"""

from collections import deque
from itertools import count

import msgspec
import pytest

from pairplay.schemas import events as ev
from pairplay.schemas.events import encode_event
from pairplay.schemas.keys import event_key
from pairplay.schemas.session import SessionConfig
from pairplay.services.game import GameLogic
from pairplay.services.learner import LearnerLogic
from pairplay.services.node import Driver
from pairplay.services.participant import ParticipantLogic
from pairplay.services.verify import verify_events

CONFIG = SessionConfig(session="t-stop", participant="sim:deaf", persona="deaf", seed=2, rounds=2, game_index=0)


def stopped_events(config: SessionConfig, k: int, reason: str = "interrupted", detail: str = "SIGINT",
                   after: int = 0) -> list:
    """The events a recorder holds of a session stopped after k deliveries: the game's shell ends it
    (`logic.end`, as services/session.py end_game); the other services go on for `after` more
    deliveries (they stop a moment later; the game refuses what reaches it after its end), and what
    was published by then is recorded (the session waits for it: services/session.py)."""
    clock = count(10**18, 1000).__next__
    learner, participant = Driver(LearnerLogic(), config.session, clock), Driver(ParticipantLogic(), config.session, clock)
    game = Driver(GameLogic(config), config.session, clock)
    recorded, pending = [], deque(game.start())

    def deliver():
        e = pending.popleft()
        recorded.append(e)
        key, payload = event_key(e.session, e.source, type(e).__name__), encode_event(e)
        for d in (learner, participant, game):
            pending.extend(d.receive(key, payload))

    for _ in range(k):
        if not pending:
            break
        deliver()
    pending.extend(game._stamp(game.logic.end(reason, detail)))
    for _ in range(after):
        if pending:
            deliver()
    return recorded + list(pending)


def full_length(config: SessionConfig) -> int:
    return len(stopped_events(config, 10**9))


def test_a_session_stopped_after_any_delivery_verifies_up_to_its_stop():
    n = full_length(CONFIG)
    for k in range(0, n, 17):  # every 17th: a few seconds; the named moments are tested below
        for after in (0, 5):
            events = stopped_events(CONFIG, k, after=after)
            result = verify_events(events)
            assert result.ok, (k, after, [(c.service, c.mismatches[:2]) for c in result.checks])
            [end] = [e for e in events if isinstance(e, ev.SessionEnded)]
            if end.reason == "interrupted":
                assert result.reach.startswith("up to where the session stopped: interrupted (SIGINT) after "
                                               f"{end.rounds_played} of 2 rounds"), result.reach


@pytest.mark.parametrize("moment", ["first pick", "between pick and suggestion", "between rounds"])
def test_the_named_moments_verify(moment):
    """The moments a new user pressed Ctrl-C at, found in the event stream rather than by timing."""
    n = full_length(CONFIG)
    whole = stopped_events(CONFIG, n)
    tags = [type(e).__name__ for e in whole]
    k = {"first pick": tags.index("CardPicked"),
         "between pick and suggestion": tags.index("SuggestionRequested") + 1,
         "between rounds": tags.index("RoundEnded") + 1}[moment]
    result = verify_events(stopped_events(CONFIG, k))
    assert result.ok and result.stopped == "interrupted (SIGINT)", [c.mismatches[:2] for c in result.checks]


@pytest.mark.parametrize("reason,detail", [("interrupted", "SIGTERM"), ("aborted", "stopped by the experimenter"),
                                           ("failed", "learner left the bus and did not come back within 30 s")])
def test_every_way_a_session_stops_verifies(reason, detail):
    events = stopped_events(CONFIG, 40, reason, detail)
    result = verify_events(events)
    assert result.ok and result.stopped.startswith(reason)


def test_a_completed_session_verifies_whole():
    result = verify_events(stopped_events(CONFIG, 10**9))  # ran to its end: the shell's end() is then []
    assert result.ok and not result.stopped and result.reach == "the whole session (2 rounds)"


def test_an_altered_event_before_the_stop_still_fails():
    events = stopped_events(CONFIG, 120)
    i = next(i for i, e in enumerate(events) if isinstance(e, ev.SuggestionMade))
    events[i] = msgspec.structs.replace(events[i], action=(events[i].action + 1) % 88)
    result = verify_events(events)
    assert not result.ok
    learner = next(c for c in result.checks if c.service == "learner")
    assert learner.mismatches[0].startswith(f"SuggestionMade seq {events[i].seq}:")


@pytest.mark.parametrize("field", ["rounds_played", "turns_in_round"])
def test_a_stop_recorded_at_the_wrong_place_fails(field):
    events = stopped_events(CONFIG, 120)
    i = next(i for i, e in enumerate(events) if isinstance(e, ev.SessionEnded))
    events[i] = msgspec.structs.replace(events[i], **{field: getattr(events[i], field) + 1})
    result = verify_events(events)
    game = next(c for c in result.checks if c.service == "game")
    assert not result.ok and game.mismatches[0].startswith("SessionEnded")


def test_a_stop_relabelled_completed_fails():
    events = stopped_events(CONFIG, 120)
    i = next(i for i, e in enumerate(events) if isinstance(e, ev.SessionEnded))
    events[i] = msgspec.structs.replace(events[i], reason="completed", detail="")
    assert not verify_events(events).ok


SAMPLE = __import__("pathlib").Path(__file__).resolve().parents[1] / "recordings" / "samples" / "sim-helmut-fmt2.mcap"


@pytest.mark.parametrize("fraction", [0.3, 0.6])
def test_a_file_cut_by_a_crash_says_so_in_its_verdict_whole_and_after_recover(fraction, tmp_path, capsys):
    """Before: a file cut by a crash (and the same after `pairplay recover`) said a plain `verify: PASS`.
    Now the verdict says the file is cut, the session's end is missing, how far it verified; exit 0
    (what it holds is right), as a session stopped by Ctrl-C."""
    from pairplay.cli.main import main
    data = SAMPLE.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[:int(len(data) * fraction)])
    assert main(["recover", str(cut), "--out", str(tmp_path / "mended.mcap")]) == 0
    capsys.readouterr()
    for path in (cut, tmp_path / "mended.mcap"):
        assert main(["replay", "--verify", str(path)]) == 0
        last = capsys.readouterr().out.strip().splitlines()[-1]
        assert last.startswith("verify: PASS as far as the file goes: the file is cut, the session's end is "
                               "missing (verified "), last
        assert " of 15 recorded whole" in last, last


def test_a_file_cut_only_in_its_index_says_its_end_is_in_it(tmp_path, capsys):
    from pairplay.cli.main import main
    data = SAMPLE.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[:len(data) - 200])
    assert main(["replay", "--verify", str(cut)]) == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last.startswith("verify: PASS; the file is cut, after its session's end was recorded"), last


def test_a_cut_file_with_a_tampered_event_still_fails(tmp_path, capsys):
    from pairplay.cli.main import main
    from pairplay.services.verify import verify_events
    events = stopped_events(CONFIG, 40)
    moved = next(i for i, e in enumerate(events) if isinstance(e, ev.SuggestionMade))
    events[moved] = msgspec.structs.replace(events[moved], action=(events[moved].action + 1) % 88)
    result = verify_events(events[:60], truncated=True)
    assert not result.ok and result.verdict == "verify: FAIL"
    assert main  # the CLI prints result.verdict (cli/replay.py)


def test_rounds_are_counted_from_1_in_the_verdict():
    """The board shows round 1 first; the verdict said `in round 0` for the first round."""
    events = stopped_events(CONFIG, 25)
    [end] = [e for e in events if isinstance(e, ev.SessionEnded)]
    assert end.round == 0
    assert "in round 1 after" in verify_events(events).reach
