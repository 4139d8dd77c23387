"""Verify's verdict does not depend on the order the recorder happened to hold events in (issue 10, item 2).

A recorder subscribes to the whole session and may write a later event of one
source before an earlier event of another that caused it (the next round's
RoundStarted before the learner's last SuggestionMade of a round). Verify feeds
the fresh services every source's events in that source's own order and holds
an input until what it depends on has been handled, so every order the file
can hold gives the same verdict; an altered derived event fails, named.
"""

import random

import msgspec
import pytest

from pairplay.schemas import events as ev
from pairplay.schemas.session import SessionConfig
from pairplay.services.verify import verify_events

from loopback_session import loopback_events


def session(persona="blind", rounds=4, seed=1, game_index=1):
    return SessionConfig(session=f"t-{persona}", participant=f"sim:{persona}", persona=persona, seed=seed,
                         rounds=rounds, game_index=game_index)


def round_start_before_last_suggestion(events, r):
    """Move RoundStarted(r) before the learner's last SuggestionMade of round r-1 (what a recorder can hold)."""
    events = list(events)
    start = next(i for i, e in enumerate(events) if isinstance(e, ev.RoundStarted) and e.round == r)
    last = max(i for i, e in enumerate(events) if isinstance(e, ev.SuggestionMade) and e.round == r - 1)
    moved = events.pop(start)
    events.insert(last, moved)
    return events


def test_a_loopback_recording_verifies():
    assert verify_events(loopback_events(session())).ok


@pytest.mark.parametrize("persona", ["blind", "deaf"])
def test_next_round_start_before_the_last_suggestion_still_passes(persona):
    events = loopback_events(session(persona))
    for r in (1, 2, 3):
        events = round_start_before_last_suggestion(events, r)
    result = verify_events(events)
    assert result.ok, [c.mismatches[:2] for c in result.checks]


def interleave(events, rng):
    """A random merge of the sources' own sequences (each source keeps its order)."""
    by_source = {}
    for e in events:
        by_source.setdefault(e.source, []).append(e)
    slots = [s for s, es in by_source.items() for _ in es]
    rng.shuffle(slots)
    its = {s: iter(es) for s, es in by_source.items()}
    return [next(its[s]) for s in slots]


@pytest.mark.parametrize("persona,seed", [("deaf", 2), ("ashley", 3)])
def test_any_merge_of_the_sources_gives_the_same_verdict(persona, seed):
    events = loopback_events(session(persona, rounds=3, seed=seed))
    rng = random.Random(seed)
    for _ in range(5):
        assert verify_events(interleave(events, rng)).ok


def test_a_source_written_out_of_its_own_order_is_put_back_in_it():
    events = loopback_events(session("deaf", rounds=2))
    game = [i for i, e in enumerate(events) if e.source == "game"]
    a, b = game[10], game[11]  # swap two of the game's events in the file
    events[a], events[b] = events[b], events[a]
    assert verify_events(events).ok


def test_one_altered_derived_event_fails_every_time_and_is_named():
    events = loopback_events(session("deaf", rounds=3))
    i = next(i for i, e in enumerate(events) if isinstance(e, ev.SuggestionMade) and e.round == 2)
    altered = events[i]
    events[i] = msgspec.structs.replace(altered, action=(altered.action + 1) % 88)
    rng = random.Random(0)
    for _ in range(10):
        result = verify_events(interleave(events, rng))
        assert not result.ok
        learner = next(c for c in result.checks if c.service == "learner")
        assert learner.mismatches and learner.mismatches[0].startswith(f"SuggestionMade seq {altered.seq}:")
