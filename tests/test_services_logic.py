"""The service logics without a network: wired through an in-memory loop they
play the very game core.simulate plays, and refuse bad input with a reason."""

import itertools
from collections import deque

import numpy as np
import pytest

from pairplay.core.personas import persona
from pairplay.core.simulate import run_games
from pairplay.replay.fold import fold_events
from pairplay.schemas import events as ev
from pairplay.schemas.envelope import stamped
from pairplay.schemas.events import encode_event
from pairplay.schemas.keys import event_key
from pairplay.schemas.config import DEFAULT_REWARD_BONUS
from pairplay.schemas.session import SessionConfig
from pairplay.services.game import GameLogic
from pairplay.services.learner import LearnerLogic
from pairplay.services.node import Driver, stream_seed
from pairplay.services.participant import ParticipantLogic


def play(config, shuffle_seed=None):
    """Run game, learner and participant drivers over an in-memory bus.

    With `shuffle_seed`, deliveries to each driver are delayed at random, so
    messages from different sources overtake each other as on a real network.
    """
    clock = itertools.count(10**18, 10**6).__next__
    drivers = [Driver(GameLogic(config), config.session, clock), Driver(LearnerLogic(), config.session, clock),
               Driver(ParticipantLogic(), config.session, clock)]
    rng = np.random.default_rng(shuffle_seed) if shuffle_seed is not None else None
    inboxes = [deque() for _ in drivers]
    log = []

    def publish(events):
        for e in events:
            log.append(e)
            item = (event_key(e.session, e.source, type(e).__name__), encode_event(e))
            for box in inboxes:
                box.append(item)

    publish(drivers[0].start())
    while any(inboxes):
        ready = [i for i, box in enumerate(inboxes) if box]
        i = ready[int(rng.integers(len(ready)))] if rng is not None else ready[0]
        key, payload = inboxes[i].popleft()
        publish(drivers[i].receive(key, payload))
    return drivers, log


def config(**kw):
    base = dict(session="t1", participant="sim:ashley", persona="ashley", seed=3, rounds=12,
                reward_bonus=DEFAULT_REWARD_BONUS)
    return SessionConfig(**{**base, **kw})


@pytest.mark.parametrize("observed", ["intended", "first-pick"])
def test_the_bus_logics_learn_exactly_what_the_study_learns(observed):
    cfg = config(observed_source=observed)
    drivers, log = play(cfg)
    study = run_games([persona("ashley")], [stream_seed(cfg)], cfg.rounds, observed_source=observed,
                      reward_bonus=cfg.reward_bonus)
    folded = fold_events(log)
    assert np.array_equal(drivers[1].logic.learner.q[0], study.q[0])
    assert np.array_equal(folded.q, study.q[0]) and folded.q_mismatches == 0
    assert [2 * t for t in folded.turns_per_round()] == list(study.picks[0])
    assert not folded.rejections and folded.ended is not None


def test_delivery_order_across_sources_does_not_change_the_result():
    cfg = config(rounds=6)
    reference = play(cfg)[0][1].logic.learner.q
    for seed in range(3):
        drivers, log = play(cfg, shuffle_seed=seed)
        assert np.array_equal(drivers[1].logic.learner.q, reference)
        assert not fold_events(log).rejections


def test_every_suggestion_gets_exactly_one_reward():
    _, log = play(config(rounds=5))
    made = {(e.round, e.turn, e.attempt) for e in log if isinstance(e, ev.SuggestionMade)}
    rewarded = [(e.round, e.turn, e.attempt) for e in log if isinstance(e, ev.RewardGiven)]
    assert sorted(rewarded) == sorted(made) and len(rewarded) == len(set(rewarded))


def test_pi_reuse_and_fixed_policies_run_and_match_the_study():
    bias = list(range(33, 33 + 24))
    bias = [a % 88 for a in bias]
    for algorithm, mode, kw in (("pi-reuse", "reuse", {"bias": np.array(bias)}),
                                ("fixed", "fixed", {"policy": np.array(bias)})):
        cfg = config(algorithm=algorithm, policy_actions=bias, rounds=4)
        drivers, log = play(cfg)
        study = run_games([persona("ashley")], [stream_seed(cfg)], cfg.rounds, mode=mode, reward_bonus=cfg.reward_bonus,
                          **kw)
        assert np.array_equal(drivers[1].logic.learner.q[0], study.q[0])
        if algorithm == "fixed":
            assert all(e.action == bias[e.state] for e in log if isinstance(e, ev.SuggestionMade))


def feed(driver, event, source="participant", seq=None):
    seen = [n for k, n in driver.last_seq.items() if k.split("/")[2] == source]
    seq = seq if seq is not None else max(seen, default=0) + 1
    e = stamped(event, session="t1", source=source, seq=seq, time_ns=seq * 10**9)
    return driver.receive(event_key("t1", source, type(event).__name__), encode_event(e))


def test_illegal_picks_are_refused_with_the_rule_and_change_nothing():
    game = Driver(GameLogic(config()), "t1", lambda: 0)
    game.start()
    out = feed(game, ev.CardPicked(round=0, turn=0, card=99))
    assert isinstance(out[0], ev.PickRejected) and "off the board" in out[0].reason
    out = feed(game, ev.CardPicked(round=0, turn=0, card=4))
    assert isinstance(out[0], ev.CardRevealed)
    out = feed(game, ev.CardPicked(round=0, turn=0, card=4))
    assert isinstance(out[0], ev.PickRejected) and "observed card" in out[0].reason
    out = feed(game, ev.CardObserved(round=0, turn=0, card=4, observed_source="intended"))
    assert isinstance(out[0], ev.MessageRejected) and "not a covered card" in out[0].reason
    out = feed(game, ev.CardObserved(round=0, turn=0, card=5, observed_source="intended"))
    assert isinstance(out[0], ev.SuggestionRequested) and out[0].observed == 5
    out = feed(game, ev.CardPicked(round=3, turn=0, card=6))
    assert isinstance(out[0], ev.PickRejected) and "for round 4, turn 1, but the game is in round 1, turn 1" \
        in out[0].reason  # counted from 1, as the board shows them
    out = feed(game, ev.CardPicked(round=0, turn=0, card=4))
    assert isinstance(out[0], ev.PickRejected) and "already face up" in out[0].reason


def test_envelope_problems_are_rejected_and_the_service_goes_on():
    game = Driver(GameLogic(config()), "t1", lambda: 0)
    game.start()
    key = event_key("t1", "participant", "CardPicked")
    cases = {
        b"{not json": "malformed",
        b'{"type":"Bogus","session":"t1"}': "malformed",
        encode_event(stamped(ev.CardPicked(round=0, turn=0, card=1), session="other", source="participant",
                             seq=1, time_ns=1)): "does not match",
    }
    for payload, reason in cases.items():
        out = game.receive(key, payload)
        assert isinstance(out[0], ev.MessageRejected) and reason in out[0].reason
    other = event_key("other", "participant", "CardPicked")
    wrong = encode_event(stamped(ev.CardPicked(round=0, turn=0, card=1), session="other", source="participant",
                                 seq=1, time_ns=1))
    assert "wrong session" in game.receive(other, wrong)[0].reason
    assert isinstance(feed(game, ev.CardPicked(round=0, turn=0, card=1), seq=5)[0], ev.CardRevealed)
    for seq in (5, 4):  # a duplicate, then one that comes too late
        out = feed(game, ev.CardPicked(round=0, turn=0, card=2), seq=seq)
        assert isinstance(out[0], ev.MessageRejected) and "not above" in out[0].reason
    assert isinstance(feed(game, ev.CardObserved(round=0, turn=0, card=2, observed_source="intended"))[0],
                      ev.SuggestionRequested)


def test_human_turns_use_the_time_rule_and_the_wrong_suggestion_button():
    cfg = config(participant="human:p1", persona="", ignore_rule="time", observed_source="first-pick")
    game, learner = Driver(GameLogic(cfg), "t1", lambda: 0), Driver(LearnerLogic(), "t1", lambda: 0)
    log = []

    def publish(events):
        for e in events:
            log.append(e)
            publish(learner.receive(event_key("t1", e.source, type(e).__name__), encode_event(e)))

    def board(event, seq, at_s):
        e = stamped(event, session="t1", source="board", seq=seq, time_ns=int(at_s * 1e9))
        publish(game.receive(event_key("t1", "board", type(event).__name__), encode_event(e)))

    publish(game.start())
    faces = log[1].faces
    miss = [0, next(c for c in range(18) if faces[c] != faces[0])]
    again = [c for c in range(18) if c not in miss][:2]
    board(ev.CardPicked(round=0, turn=0, card=miss[0]), 1, 10.0)
    board(ev.WrongSuggestionPressed(round=0, turn=0), 2, 10.5)
    board(ev.CardPicked(round=0, turn=0, card=miss[1]), 3, 12.0)  # 2 s after the first: considered
    board(ev.CardPicked(round=0, turn=1, card=again[0]), 4, 20.0)
    board(ev.CardPicked(round=0, turn=1, card=again[1]), 5, 20.4)  # 0.4 s: ignored (thesis 7.1.2)
    rewards = [(r.turn, r.attempt, r.reward, r.learned) for r in log if isinstance(r, ev.RewardGiven)]
    assert rewards[:2] == [(0, 0, -3.0, True), (0, 1, -1.0, True)]
    assert rewards[2][:2] == (1, 0) and rewards[2][2:] == (0.0, False)
    resolved = [e for e in log if isinstance(e, ev.TurnResolved)]
    assert [t.ignored_by_time for t in resolved] == [False, True]
    assert not any(isinstance(e, ev.MessageRejected) for e in log)
