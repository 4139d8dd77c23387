"""The board's model folds events that overtook each other on the bus (found by the console's browser test).

A suggestion (learner) can reach the board before the game's request for it,
and a request before the first card it follows: the board must still show the
suggestion, or it waits in "thinking" and the wrong-suggestion button stays off.
"""

from __future__ import annotations

import itertools

import pytest

from pairplay.schemas import events as ev
from pairplay.schemas.session import SessionConfig
from pairplay.services.lab.model import LabModel

CONFIG = SessionConfig(session="s", participant="human:p01", seed=0, rounds=1, observed_source="first-pick",
                       ignore_rule="time")
TURN = [
    ev.CardRevealed(round=0, turn=0, card=3, face=1, pick=0),
    ev.SuggestionRequested(round=0, turn=0, attempt=0, state=5, observed=3, match=9, covered_mask=(1 << 18) - 1 - 8),
    ev.SuggestionMade(round=0, turn=0, attempt=0, state=5, action=35, chosen_by="explore", epsilon=0.9, alpha=0.5,
                      psi=0.0, observed=3, target=9),
]


@pytest.mark.parametrize("order", list(itertools.permutations(range(3))), ids=str)
def test_the_suggestion_survives_any_order_of_its_turn(order):
    m = LabModel()
    for e in (ev.SessionStarted(config=CONFIG), ev.RoundStarted(round=0, faces=[i // 2 for i in range(18)])):
        m.apply(e)
    for i in order:
        m.apply(TURN[i])
    assert m.phase() == "second" and m.suggestion["attempt"] == 0 and m.first == 3
    # a second request (wrong-suggestion press) clears the old suggestion until its answer
    m.apply(ev.SuggestionRequested(round=0, turn=0, attempt=1, state=5, observed=3, match=9, covered_mask=0))
    assert m.phase() == "thinking"


def test_the_views_are_json_with_the_envelope_times_of_today():
    """Event times are Nanos (an int subclass with JSON hooks, schemas/envelope.py); the pages' encoder
    knows no hooks, so every time in a view must be a plain int (the mirror stalled on RobotActed)."""
    import msgspec

    from pairplay.schemas.envelope import stamped
    from pairplay.schemas.events import decode_event, encode_event
    from pairplay.schemas.robot import RobotActed
    m = LabModel()
    for e in (ev.SessionStarted(config=CONFIG), ev.RoundStarted(round=0, faces=[i // 2 for i in range(18)]), *TURN,
              RobotActed(round=0, turn=0, attempt=0, action=35, backend="virtual", outcome="done", commands=["say"],
                         received_ns=10**18, sent_ns=10**18 + 1, acked_ns=10**18 + 2, done_ns=10**18 + 3)):
        # as the hub gets them: stamped, through the bus's JSON (times come back as Nanos)
        m.apply(decode_event(encode_event(stamped(e, session="s", source="x", seq=1, time_ns=10**18))))
    for view in (m.board_view(), m.mirror_view()):
        msgspec.json.Encoder().encode(view)
