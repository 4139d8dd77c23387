"""Frames of reference (thesis 7.3, chapter 8 future work 2): the maps, the mirrored user, calibration, merging."""

import csv

import numpy as np
import pytest

from pairplay.core import calibration
from pairplay.core.actions import ACTION_NAMES, HEARING_EXACT, N_ACTIONS, code_of_parts
from pairplay.core.frame_study import ARMS, frame_experiment
from pairplay.core.frames import (ACTION_MAP, CARD_MAP, CELL_MAP, FRAME_HEAR, FRAME_PERSONAS, FRAME_VIS, FRAMES,
                                  HEARING_MAP, N_FRAMES, STATE_MAP, VISUAL_MAP, frame_index, mismatch,
                                  read_in_frame, to_frame)
from pairplay.core.geometry import ALL_CARDS, CELL_INDEX, N_CARDS, N_STATES, STATE_NAMES, card_of, state_of
from pairplay.core.interpretation import HEAR_SET, VIS_SET, hearing_meaning, visual_meaning
from pairplay.core.personas import PERSONAS
from pairplay.core.rng import UniformStream
from pairplay.core.simulate import run_games
from pairplay.core.user import SimulatedUsers
from pairplay.schemas.config import Persona

COLUMNS, ROWS_, BOTH = frame_index("mirror-columns"), frame_index("mirror-rows"), frame_index("mirror-both")
MAPS = {"card": CARD_MAP, "cell": CELL_MAP, "state": STATE_MAP, "action": ACTION_MAP}


@pytest.mark.parametrize("name", MAPS)
def test_every_map_is_an_involution_and_frames_compose_by_xor(name):
    table = MAPS[name]
    assert np.array_equal(table[0], np.arange(table.shape[1]))  # the robot's frame moves nothing
    for f in range(N_FRAMES):
        assert np.array_equal(table[f][table[f]], np.arange(table.shape[1])), f
        assert sorted(table[f]) == list(range(table.shape[1]))  # a permutation
        for g in range(N_FRAMES):
            assert np.array_equal(table[f][table[g]], table[mismatch(f, g)])


def _action(speech=0, facial=0, head=0, gaze=0):
    return code_of_parts(speech, facial, head, gaze)


@pytest.mark.parametrize("frame, before, after", [
    (COLUMNS, _action(speech=5), _action(speech=6)),  # "Maybe left" -> "Maybe right"
    (COLUMNS, _action(speech=3), _action(speech=3)),  # "Maybe up" stays
    (COLUMNS, _action(head=6), _action(head=7)),  # turn up-left -> up-right
    (ROWS_, _action(head=6), _action(head=8)),  # turn up-left -> down-left
    (ROWS_, _action(speech=3, head=4), _action(speech=4, head=5)),  # up + up -> down + down
    (BOTH, _action(speech=2, head=9), _action(speech=2, head=6)),  # exact stays; down-right -> up-left
    (BOTH, _action(facial=1, gaze=1), _action(facial=1, gaze=1)),  # smile and gaze are physical
    (BOTH, _action(speech=1, head=1), _action(speech=1, head=1)),  # "It is the right card" + nod
])
def test_the_action_map_on_hand_cases(frame, before, after):
    assert ACTION_MAP[frame, before] == after, (ACTION_NAMES[before], ACTION_NAMES[ACTION_MAP[frame, before]])


def test_cards_cells_and_states_on_hand_cases():
    assert CARD_MAP[COLUMNS, card_of(0, 0)] == card_of(0, 5)  # column 1 counted from the right
    assert CARD_MAP[ROWS_, card_of(0, 1)] == card_of(2, 1)
    assert CARD_MAP[BOTH, card_of(1, 2)] == card_of(1, 3)
    assert CELL_MAP[COLUMNS, CELL_INDEX["TOP_LEFT"]] == CELL_INDEX["TOP_RIGHT"]
    assert CELL_MAP[ROWS_, CELL_INDEX["LEFT"]] == CELL_INDEX["LEFT"]
    assert CELL_MAP[BOTH, CELL_INDEX["MATCH"]] == CELL_INDEX["MATCH"]
    name = {n: i for i, n in enumerate(STATE_NAMES)}
    assert STATE_MAP[COLUMNS, name["RIGHT_L0"]] == name["LEFT_L0"]
    assert STATE_MAP[ROWS_, name["TOP_L1"]] == name["BOTTOM_L1"]
    assert STATE_MAP[BOTH, name["NOT_ONE_CARD"]] == name["NOT_ONE_CARD"]


def test_a_mirrored_user_reads_appendix_b_through_the_action_map_and_exact_coordinates_mirrored():
    assert np.array_equal(FRAME_HEAR[0], HEAR_SET) and np.array_equal(FRAME_VIS[0], VIS_SET)
    for f in range(N_FRAMES):
        hear_map, vis_map = HEARING_MAP[f], VISUAL_MAP[f]
        for h in range(HEAR_SET.shape[2]):
            if h == HEARING_EXACT:  # "Try at row x and column y" names the mirrored card
                assert (FRAME_HEAR[f, :, :, h] == (1 << CARD_MAP[f])[None, :]).all()
            else:
                assert np.array_equal(FRAME_HEAR[f, :, :, h], HEAR_SET[:, :, hear_map[h]])
        assert np.array_equal(FRAME_VIS[f], VIS_SET[:, :, vis_map])


def test_the_frame_tables_are_appendix_b_read_meaning_by_meaning_in_each_frame():
    for f in range(N_FRAMES):
        for obs in range(N_CARDS):
            for match in range(N_CARDS):
                for h in range(HEAR_SET.shape[2]):
                    assert FRAME_HEAR[f, obs, match, h] == read_in_frame(f, hearing_meaning(h)[0], obs, match)
                for v in range(VIS_SET.shape[2]):
                    assert FRAME_VIS[f, obs, match, v] == read_in_frame(f, visual_meaning(v)[0], obs, match)


def test_states_on_a_mirrored_board_are_the_state_map():
    rng = np.random.default_rng(5)
    for _ in range(300):
        observed, match = rng.choice(N_CARDS, 2, replace=False)
        covered = int(rng.integers(0, ALL_CARDS + 1)) | (1 << int(match))
        covered &= ~(1 << int(observed))
        s = state_of(int(observed), int(match), covered)
        for f in range(N_FRAMES):
            mirrored = sum(1 << int(CARD_MAP[f, c]) for c in range(N_CARDS) if covered >> c & 1)
            assert state_of(int(CARD_MAP[f, observed]), int(CARD_MAP[f, match]), mirrored) == STATE_MAP[f, s]


def test_to_frame_moves_policies_and_q_tables_and_back():
    rng = np.random.default_rng(2)
    policy, q = rng.integers(0, N_ACTIONS, (3, N_STATES)), rng.normal(size=(3, N_STATES, N_ACTIONS))
    frames = np.array([0, COLUMNS, BOTH])
    moved, moved_q = to_frame(policy, frames, q)
    assert np.array_equal(moved[1], ACTION_MAP[COLUMNS, policy[1]])
    assert moved_q[2, 4, 7] == q[2, 4, ACTION_MAP[BOTH, 7]]
    back, back_q = to_frame(moved, frames, moved_q)
    assert np.array_equal(back, policy) and np.array_equal(back_q, q)
    assert np.array_equal(to_frame(policy[1], COLUMNS), moved[1])


def _without_exact_speech(policy):
    h, v = policy // 11, policy % 11
    return np.where(h == HEARING_EXACT, 0, h) * 11 + v


def test_a_mirrored_user_plays_the_game_a_thesis_user_plays_with_the_actions_mirrored():
    # the same draws: the only difference a frame makes is which cards an action names
    rng = np.random.default_rng(0)
    personas = [PERSONAS["tatiana"], PERSONAS["helmut"], PERSONAS["deaf"]] * 2
    policies = _without_exact_speech(rng.integers(0, N_ACTIONS, (len(personas), N_STATES)))
    frames = np.array([COLUMNS, ROWS_, BOTH, 1, 2, 3])
    mirrored = run_games(personas, list(range(6)), 15, mode="fixed", policy=policies, frames=frames)
    thesis = run_games(personas, list(range(6)), 15, mode="fixed", policy=to_frame(policies, frames))
    assert np.array_equal(mirrored.picks, thesis.picks)
    shown_raw = run_games(personas, list(range(6)), 15, mode="fixed", policy=policies)
    assert not np.array_equal(mirrored.picks, shown_raw.picks)


def test_the_live_simulated_user_reads_in_its_frame():
    tatiana = PERSONAS["tatiana"]  # focus 6: always considers; hears and sees
    maybe_left = _action(speech=5)
    observed, match = card_of(1, 2), card_of(1, 0)
    picks = {}
    for frame in (0, COLUMNS):
        users = SimulatedUsers([tatiana], UniformStream([1], "user"), frames=frame)
        covered = ALL_CARDS & ~(1 << observed)
        users.first_pick(covered, np.arange(N_CARDS) ^ 1)
        r = users.respond(np.array([maybe_left]), np.array([observed]), np.array([match]), np.array([match]),
                          np.array([False]), np.array([covered]))
        picks[frame] = int(r.second[0])
    assert picks[0] in (card_of(1, 0), card_of(1, 1))  # the robot's left
    assert picks[COLUMNS] in (card_of(1, 3), card_of(1, 4), card_of(1, 5))  # the mirrored user's left
    with pytest.raises(ValueError, match="frame"):
        SimulatedUsers([tatiana], UniformStream([1], "user"), frames=4)


def test_calibration_recovers_every_frame_persona():
    framed = list(FRAME_PERSONAS.values())
    assert {fp.frame for fp in framed} == {"canonical", "mirror-columns", "mirror-rows", "mirror-both"}
    assert not set(FRAME_PERSONAS) & set(PERSONAS)  # their own table, not the default study's
    acc = calibration.accuracy([fp.persona for fp in framed], [frame_index(fp.frame) for fp in framed],
                               (1, 4, 8), 200, np.random.default_rng(11))
    assert (acc[:, 1] >= 0.95).all() and (acc[:, 2] >= 0.99).all(), acc


def test_calibration_of_a_deaf_or_blind_user_uses_the_other_kind():
    # a deaf user never hears the exact position and a blind one never sees the head: the other kind tells
    deaf, blind = PERSONAS["deaf"], PERSONAS["blind"]
    acc = calibration.accuracy([deaf, blind], [BOTH, COLUMNS], (8,), 100, np.random.default_rng(3))
    assert (acc >= 0.95).all(), acc


def test_one_followed_suggestion_tells_the_frame_and_a_random_pick_tells_nothing():
    trials = calibration.design(4, 1, np.random.default_rng(0))
    named = calibration.named_cards(trials)[:, 0]  # (sessions, frames)
    assert (np.bitwise_count(named) == 1).all()
    truth = np.arange(4)
    picks = np.array([int(named[i, f]).bit_length() - 1 for i, f in enumerate(truth)])[:, None]
    frame, post = calibration.infer(trials, picks)
    assert np.array_equal(frame, truth) and (post[np.arange(4), truth] > 0.5).all()
    nowhere = [next(c for c in range(N_CARDS) if (trials.covered[i, 0] >> c & 1) and not any(
        int(named[i, f]) >> c & 1 for f in range(4))) for i in range(4)]
    frame, post = calibration.infer(trials, np.array(nowhere)[:, None])
    assert (frame == 0).all() and np.allclose(post, 0.25)  # no evidence: ties go to the robot's frame


def test_calibration_design_names_four_different_cards_in_every_trial():
    trials = calibration.design(50, 6, np.random.default_rng(9))
    named = calibration.named_cards(trials)
    for f in range(4):
        for g in range(f + 1, 4):
            assert not (named[..., f] & named[..., g]).any()
    assert (named > 0).all()
    with pytest.raises(ValueError):
        calibration.design(1, 0, np.random.default_rng(0))


def test_merging_with_calibration_beats_merging_without():
    framed = list(FRAME_PERSONAS.values())
    exp = frame_experiment(framed, 3, replicates=2, rounds=200, eval_rounds=30, accuracy_sessions=20, lengths=(4,))
    again = frame_experiment(framed, 3, replicates=2, rounds=200, eval_rounds=30, accuracy_sessions=20,
                             lengths=(4,))
    assert np.array_equal(exp.picks, again.picks)
    assert exp.picks.shape == (len(ARMS), 2, len(framed)) and (exp.picks >= 18).all()
    without, with_ = exp.picks[ARMS.index("merge without calibration")], exp.picks[ARMS.index("merge with calibration")]
    mirrored = exp.frame != 0
    assert (with_[:, mirrored].mean(axis=1) + 2 < without[:, mirrored].mean(axis=1)).all(), exp.picks
    assert with_.mean() < without.mean()


def test_the_report_section_writes_its_table_and_asks_for_its_figure(tmp_path):
    from pairplay.report.future_frames import frames_section
    from pairplay.report.study import markdown_table
    framed = list(FRAME_PERSONAS.values())
    exp = frame_experiment(framed, 1, replicates=2, rounds=40, eval_rounds=10, accuracy_sessions=10, lengths=(1, 4))
    drawn = []
    lines = frames_section(tmp_path, exp, markdown_table, lambda name, *args: drawn.append((name, args)))
    assert drawn[0][0] == "frame_calibration" and drawn[0][1][4] == tmp_path / "frames.png"
    text = "\n".join(lines)
    assert text.startswith("## Frame-of-reference calibration") and "![frames](frames.png)" in text
    rows = list(csv.reader(open(tmp_path / "frames.csv")))
    assert rows[0][1:5] == list(ARMS) and len(rows) == 1 + len(framed) + 3
    assert [r[0] for r in rows[1:1 + len(framed)]] == [fp.persona.name for fp in framed]
    from pairplay.report import plots
    plots.draw("frame_calibration", *drawn[0][1])
    assert (tmp_path / "frames.png").stat().st_size > 10_000


def test_a_framed_persona_names_a_known_frame():
    from pairplay.core.frames import parse_frame_personas
    good = b'{"note": "", "personas": [{"frame": "mirror-rows", "persona": {"key": "x", "name": "X", ' \
           b'"focus": 3, "memory": 3, "hearing": 3, "sight": 3}}]}'
    assert parse_frame_personas(good)["x"].persona == Persona("x", "X", 3, 3, 3, 3)
    with pytest.raises(Exception, match="unknown frame"):
        parse_frame_personas(good.replace(b"mirror-rows", b"sideways"))
    assert len(FRAMES) == N_FRAMES == 4
