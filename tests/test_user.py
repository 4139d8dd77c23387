"""The simulated user of thesis 6.1.3: picks, perception, interpretation and memory."""

import numpy as np
import pytest

from pairplay.core.actions import code_of_parts
from pairplay.core.geometry import ALL_CARDS, card_of
from pairplay.core.user import DRAWS_PER_TURN, SimulatedUsers, known_partners
from pairplay.schemas.config import Persona

FACES = np.array([0, 1, 2, 3, 4, 5, 6, 7, 8, 0, 1, 2, 3, 4, 5, 6, 7, 8])
PARTNER = np.array([(c + 9) % 18 for c in range(18)])[None]


class Script:
    """A 'user' stream that plays back the given draws (one row per turn)."""

    role = "user"
    n_games = 1

    def __init__(self, *rows):
        self.rows = [np.array([r], dtype=float) for r in rows]

    def take(self, k, games=None):
        assert k == DRAWS_PER_TURN
        return self.rows.pop(0)


def user(focus=6, memory=3, hearing=6, sight=6, draws=()):
    p = Persona(key="t", name="T", focus=focus, memory=memory, hearing=hearing, sight=sight)
    return SimulatedUsers([p], Script(*draws))


def a(*cards):
    return np.array(list(cards))


def mask(*cards):
    m = 0
    for c in cards:
        m |= 1 << c
    return m


def remembered(u):
    return [c for c in range(18) if u.memory[0] >> c & 1]


def test_memory_holds_memory_plus_one_cards_and_forgets_the_oldest():
    u = user(memory=2)  # m = 3
    u.end_turn(a(0), a(1), a(False))
    assert remembered(u) == [0, 1]
    u.end_turn(a(2), a(3), a(False))  # 4 cards for 3 places: card 0 (oldest) leaves
    assert remembered(u) == [1, 2, 3]
    u.end_turn(a(4), a(5), a(False))
    assert remembered(u) == [3, 4, 5]


def test_matched_cards_leave_memory_and_a_new_deal_empties_it():
    u = user(memory=5)
    u.end_turn(a(0), a(1), a(False))
    u.end_turn(a(10), a(2), a(False))
    u.end_turn(a(1), a(10), a(True))  # 1 and 10 are a pair: matched, forgotten
    assert remembered(u) == [0, 2]
    u.new_round()
    assert remembered(u) == []


def test_first_pick_takes_a_remembered_pair_else_an_unknown_covered_card():
    u = user(memory=5, draws=[(0.0, 0, 0, 0, 0), (0.99, 0, 0, 0, 0), (0.0, 0, 0, 0, 0)])
    u.end_turn(a(3), a(12), a(False))  # cards 3 and 12 (a pair) seen in one turn, remembered
    assert u.first_pick(a(ALL_CARDS), PARTNER)[0] == 3  # the lower card of the pair with u = 0
    assert u.first_pick(a(ALL_CARDS), PARTNER)[0] == 12  # the other with u = 0.99
    u2 = user(memory=5, draws=[(0.0, 0, 0, 0, 0)])
    u2.end_turn(a(0), a(1), a(False))  # two different faces: no pair known
    assert u2.first_pick(a(ALL_CARDS), PARTNER)[0] == 2  # lowest covered card not remembered


def test_the_user_only_knows_partners_it_has_seen():
    seen = -np.ones(18, dtype=int)
    seen[[0, 9, 4]] = [0, 0, 4]
    table = known_partners(seen)[0]
    assert table[0] == 9 and table[9] == 0 and table[4] == 18 and table[7] == 18


def test_a_remembered_match_is_picked_and_not_learned_from():
    u = user(draws=[(0.0, 0.5, 0.0, 0.0, 0.0)])
    u.end_turn(a(9), a(5), a(False))  # saw 9 (pair of 0) in a missed turn
    first = u.first_pick(a(ALL_CARDS), PARTNER)
    assert first[0] == 0  # no whole pair remembered: the lowest unknown card with u = 0
    covered = a(ALL_CARDS & ~1)
    intended, from_memory = u.intend(first, a(9), covered)
    assert from_memory[0] and intended[0] == 9
    r = u.respond(a(code_of_parts(6, 0, 0, 0)), intended, a(9), intended, from_memory, covered)
    assert r.second[0] == 9 and not r.considered[0]


def test_an_ignored_suggestion_leaves_the_intended_card():
    # focus 3: p = 0.4; the focus draw 0.5 ignores the suggestion
    u = user(focus=3, draws=[(0.0, 0.0, 0.5, 0.0, 0.0)])
    first = u.first_pick(a(ALL_CARDS), PARTNER)
    covered = a(ALL_CARDS & ~(1 << first[0]))
    intended, from_memory = u.intend(first, PARTNER[:, first[0]], covered)
    exact = code_of_parts(2, 0, 0, 0)  # "Try at row x and column y": would give the match
    r = u.respond(a(exact), intended, PARTNER[:, first[0]], intended, from_memory, covered)
    assert not r.considered[0] and r.second[0] == intended[0] != 9


def _respond(u, action, observed, match, covered):
    return u.respond(a(action), a(observed), a(match), a(observed), a(False), a(covered))


@pytest.mark.parametrize("hearing, u_hear, expected", [(6, 0.99, {9}), (4, 0.59, {9}), (4, 0.61, None), (1, 0.0, None)])
def test_speech_is_heard_with_probability_hearing_minus_one_times_0_2(hearing, u_hear, expected):
    u = user(hearing=hearing, draws=[(0, 0, 0.0, u_hear, 0.5)])
    u._u = u.stream.take(DRAWS_PER_TURN)
    covered = ALL_CARDS & ~(1 << 17)
    r = _respond(u, code_of_parts(2, 0, 0, 0), 3, 9, covered)
    assert r.considered[0] and r.consistent[0]
    if expected:
        assert r.candidates[0] == mask(*expected) and r.second[0] == 9
    else:
        assert r.candidates[0] == covered  # not heard: the whole NIS


def test_a_blind_user_sees_no_visual_part_and_partial_sight_sees_head_only():
    covered = ALL_CARDS & ~(1 << 17)
    gaze_and_smile = [code_of_parts(0, 0, 0, 1), code_of_parts(0, 1, 0, 0)]
    head_right = code_of_parts(0, 0, 3, 0)
    for sight, action, narrowed in [(1, head_right, False), (2, head_right, True), (2, gaze_and_smile[0], False),
                                    (2, gaze_and_smile[1], False), (3, gaze_and_smile[1], True),
                                    (4, gaze_and_smile[0], False), (5, gaze_and_smile[0], True)]:
        u = user(sight=sight, draws=[(0, 0, 0.0, 0.0, 0.0)])
        u._u = u.stream.take(DRAWS_PER_TURN)
        r = _respond(u, action, card_of(0, 2), card_of(0, 4), covered)
        assert (r.candidates[0] != covered) == narrowed, (sight, action)


def test_an_inconsistent_action_falls_back_to_the_nis():
    u = user(draws=[(0, 0, 0.0, 0.0, 0.0)])
    u._u = u.stream.take(DRAWS_PER_TURN)
    covered = ALL_CARDS & ~(1 << 17)
    down_up = code_of_parts(4, 0, 4, 0)  # "Maybe down" with the head up (figure 6.3)
    r = _respond(u, down_up, card_of(1, 2), card_of(0, 2), covered)
    assert r.considered[0] and not r.consistent[0] and r.candidates[0] == 0
    assert r.second[0] == 0  # the lowest card of the NIS with u = 0


def test_candidates_exclude_cards_the_user_remembers():
    u = user(memory=5, draws=[(0, 0, 0.0, 0.0, 0.99)])
    u.end_turn(a(card_of(1, 4)), a(card_of(1, 5)), a(False))
    u._u = u.stream.take(DRAWS_PER_TURN)
    covered = ALL_CARDS & ~(1 << 17)
    right = code_of_parts(6, 0, 0, 0)  # "Maybe right" from (1, 2): (1,3) (1,4) (1,5)
    r = _respond(u, right, card_of(1, 2), card_of(1, 3), covered)
    assert r.candidates[0] == mask(card_of(1, 3)) and r.second[0] == card_of(1, 3)


def test_traces_show_the_nis_and_rewards_of_the_suggestion_moment():
    """trace["nis"] is the NIS the user read the suggestion against (before the turn's
    memory update), and a suggestion pointing away from the match earns no bonus."""
    from pairplay.core.personas import PERSONAS
    from pairplay.core.simulate import run_games
    wrong_card = code_of_parts(1, 0, 0, 0)  # "It is the right card": the observed card
    t = run_games([PERSONAS["tatiana"]] * 3, [1, 2, 3], 5, mode="fixed", policy=np.full((3, 24), wrong_card),
                  record="all").trace
    assert (np.diff(t["step"]) >= 0).all() and t["step"].size > 3 * 5 * 9  # lockstep order, every turn
    unaided = t["from_memory"] == 0
    assert unaided.any() and ((t["nis"][unaided] >> t["observed"][unaided]) & 1 == 1).all()
    read = t["considered"] == 1
    away = read & (t["observed"] != t["match"])  # a certain miss
    assert away.any() and (t["reward"][away] == -1.0).all()
    assert (t["reward"][read & (t["observed"] == t["match"])] == 2.0).all()


def test_a_batchs_persona_figures_are_each_personas_own():
    """persona_arrays / reading_codes compute each distinct persona once: a mixed, repeated batch gets
    exactly the rows each persona gets alone, in the batch's order."""
    from pairplay.core.personas import PERSONAS, READING_PERSONAS
    from pairplay.core.user import persona_arrays, reading_codes
    pool = list(PERSONAS.values()) + list(READING_PERSONAS.values())
    batch = [pool[i * 7 % len(pool)] for i in range(50)] + [Persona(key="copy", name="Copy", memory=3, focus=2, hearing=1, sight=4)]
    got = persona_arrays(batch)
    for g, p in enumerate(batch):
        alone = persona_arrays([p])
        assert all(np.array_equal(a[g], b[0]) for a, b in zip(got, alone))
        assert reading_codes(batch)[g] == reading_codes([p])[0]
    assert got[3].shape == (len(batch), 3) and got[3].flags.c_contiguous
    assert all(a.shape[0] == 0 for a in persona_arrays([])) and reading_codes([]).shape == (0,)


def test_stream_keys_are_each_games_keys():
    from pairplay.core.rng import ROLES, stream_key, stream_keys
    seeds = [0, 5, 2**64 - 1, 2**63, 5]  # (-1 was here: it aliased 2**64 - 1; refused now, tests/test_seeds.py)
    for roles in (ROLES, ("deal", "user")):
        keys = stream_keys(seeds, roles)
        assert keys.shape == (5, 4) and keys.dtype == np.uint64
        for g, s in enumerate(seeds):
            assert [int(k) for k in keys[g]] == [stream_key(s, r) if r in roles else 0 for r in ROLES]
    with pytest.raises(ValueError, match="unknown role"):
        stream_keys(seeds, ("dealer",))
    assert stream_keys([]).shape == (0, 4)
