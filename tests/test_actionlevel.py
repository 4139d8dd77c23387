"""Action-level user information and combination (core/actionlevel.py) on hand-made Q-tables."""

import numpy as np
import pytest

from pairplay.core.actionlevel import (action_values, combine_actions, extract_action_info, whole_actions)
from pairplay.core.actions import code_of_parts
from pairplay.core.combine import User, combine
from pairplay.core.geometry import CELL_INDEX, N_STATES, STATE_INDEX
from pairplay.schemas.policy import UserInfo

S = int(STATE_INDEX[CELL_INDEX["TOP_LEFT"], 0])
UP_LEFT_WORDS = code_of_parts(3, 0, 2, 0)  # "Maybe up" + turn left
LEFT_UP_WORDS = code_of_parts(5, 0, 4, 0)  # "Maybe left" + turn up
EXACT = code_of_parts(2, 0, 0, 0)
EXACT_GAZE, EXACT_HEAD_UP = code_of_parts(2, 0, 0, 1), code_of_parts(2, 0, 4, 0)
ALONE = [code_of_parts(3, 0, 0, 0), code_of_parts(0, 0, 2, 0), code_of_parts(5, 0, 0, 0), code_of_parts(0, 0, 4, 0)]


def user_tables(actions, values):
    """Policies acting `actions[i]` in state S (nothing elsewhere) and Q-tables holding `values[i]` there."""
    n = len(actions)
    policies = np.zeros((n, N_STATES), dtype=np.int64)
    q = np.zeros((n, N_STATES, 88))
    for i in range(n):
        policies[i, S] = actions[i]
        for a, v in values[i].items():
            q[i, S, a] = v
    return policies, q


def test_two_wholes_with_one_meaning_are_synonyms_not_incompatibilities():
    rejected = {a: -1.0 for a in ALONE}
    policies, q = user_tables([UP_LEFT_WORDS, LEFT_UP_WORDS],
                              [{UP_LEFT_WORDS: 1.5, LEFT_UP_WORDS: 1.2, **rejected}, {LEFT_UP_WORDS: 1.6, **rejected}])
    prof = extract_action_info(policies, q)
    assert prof.algorithm3.speech == prof.algorithm3.head == 1 / 23  # algorithm 3: speech and head disagree in S
    assert prof.info.speech == prof.info.head == 0 and prof.synonym_states == [S]
    assert prof.wholes == [(S, UP_LEFT_WORDS), (S, LEFT_UP_WORDS)]
    assert prof.info.facial == prof.algorithm3.facial and prof.info.gaze == prof.algorithm3.gaze


def test_an_impaired_channel_stays_counted():
    """A blind user: the head parts differ while the words alone carry the meaning, so they are no wholes."""
    head_left, head_up = code_of_parts(2, 0, 2, 0), code_of_parts(2, 0, 4, 0)
    policies, q = user_tables([head_left, head_up], [{head_left: 2.0, EXACT: 2.0}, {head_up: 2.0, EXACT: 2.0}])
    prof = extract_action_info(policies, q)
    assert prof.info.head == prof.algorithm3.head == 1 / 23 and prof.head_states == [S] and not prof.wholes


def test_an_unrecognised_action_or_parts_not_rejected_keep_the_incompatibility():
    rejected = {a: -1.0 for a in ALONE}
    untrained = user_tables([UP_LEFT_WORDS, LEFT_UP_WORDS], [{UP_LEFT_WORDS: 1.5, **rejected}, {LEFT_UP_WORDS: -0.2}])
    assert extract_action_info(*untrained).info.speech == 1 / 23
    unsure = {a: -0.4 for a in ALONE}  # parts alone lost, but by less than the margin: no evidence of a whole
    weak = user_tables([UP_LEFT_WORDS, LEFT_UP_WORDS], [{UP_LEFT_WORDS: 1.5, **unsure}, {LEFT_UP_WORDS: 1.6}])
    prof = extract_action_info(*weak)
    assert prof.info.speech == 1 / 23 and prof.wholes == []


def test_values_average_only_the_policies_that_tried_an_action():
    q = np.zeros((3, N_STATES, 88))
    q[0, S, 5], q[1, S, 5], q[2, S, 6] = 1.0, 2.0, -1.0
    v = action_values(q)
    assert v[S, 5] == 1.5 and v[S, 6] == -1.0 and v[S, 7] == 0.0


def test_a_whole_needs_both_parts_and_both_parts_alone_rejected():
    v = np.zeros((N_STATES, 88))
    v[S, UP_LEFT_WORDS] = 1.0
    v[S, ALONE[0]] = v[S, ALONE[1]] = -1.0
    assert whole_actions(v)[S, UP_LEFT_WORDS] and whole_actions(v).sum() == 1
    v[S, ALONE[1]] = 0.5  # the head turn alone works: not a whole
    assert not whole_actions(v).any()


def test_shapes_must_agree():
    with pytest.raises(ValueError, match="2 policies but 1 Q-tables"):
        extract_action_info(np.zeros((2, N_STATES), dtype=np.int64), np.zeros((1, N_STATES, 88)))


def _user(name, action):
    policy = np.zeros(N_STATES, dtype=np.int64)
    policy[S] = action
    return User(name, policy, np.zeros((N_STATES, 88)), UserInfo(0.0, 0.0, False, True, 23))


def test_combination_keeps_a_whole_algorithm_4_would_split():
    """Duo reads the words only with the head; algorithm 4 sums head up + gaze to gaze (table 5.2)."""
    duo, other = _user("duo", EXACT_HEAD_UP), _user("other", EXACT_GAZE)
    v_duo, v_other = np.zeros((N_STATES, 88)), np.zeros((N_STATES, 88))
    v_duo[S, EXACT_HEAD_UP], v_duo[S, EXACT_GAZE] = 2.0, -0.5
    v_other[S, EXACT_HEAD_UP], v_other[S, EXACT_GAZE] = 1.0, 2.0
    assert combine([duo, other]).policy[S] == EXACT_GAZE
    merged = combine_actions([duo, other], [v_duo, v_other])
    assert merged.policy[S] == EXACT_HEAD_UP and merged.rules[S].endswith("whole=chosen(2 of 2)")
    others = [s for s in range(N_STATES) if s != S]
    assert (merged.policy[others] == combine([duo, other]).policy[others]).all()
    assert all(merged.rules[s].endswith("whole=kept") for s in others)


def test_combination_keeps_algorithm_4_where_it_is_as_widely_recognised_as_any():
    duo, other = _user("duo", EXACT_HEAD_UP), _user("other", EXACT_GAZE)
    v = np.zeros((N_STATES, 88))
    v[S, EXACT_GAZE] = v[S, EXACT_HEAD_UP] = 1.0
    merged = combine_actions([duo, other], [v, v])
    assert merged.policy[S] == EXACT_GAZE and merged.rules[S].endswith("whole=kept")
    with pytest.raises(ValueError, match="one value table per user"):
        combine_actions([duo, other], [v])


def test_ties_go_to_the_larger_sum_of_values_then_the_lowest_code():
    a_user, b_user = _user("a", EXACT_HEAD_UP), _user("b", EXACT_GAZE)
    va, vb = np.zeros((N_STATES, 88)), np.zeros((N_STATES, 88))
    va[S, EXACT_HEAD_UP], vb[S, EXACT_HEAD_UP] = 1.0, -1.0  # merged gaze: recognised by nobody
    va[S, EXACT], vb[S, EXACT] = 0.5, 0.5  # "exact" alone: recognised by both, sum 1.0
    merged = combine_actions([a_user, b_user], [va, vb])
    assert merged.policy[S] == EXACT


# --- the study report's experiment and section, and `pairplay profile --actions` ----------------

@pytest.fixture(scope="module")
def experiment():
    from pairplay.core.actionlevel import action_level_experiment
    return action_level_experiment(seed=3, rounds=40, eval_games=1, eval_rounds=4)


def test_the_experiment_reuses_the_study_games_of_the_partners_exactly(experiment):
    from pairplay.core.actionlevel import GAMES, action_level_experiment
    from pairplay.core.personas import PERSONAS
    from pairplay.core.study import train
    study = train([PERSONAS[k] for k in ("tatiana", "deaf", "blind", "ashley")], GAMES, 40, 3)
    again = action_level_experiment(seed=3, rounds=40, training=study, eval_games=1, eval_rounds=4)
    assert (again.picks == experiment.picks).all() and (again.replicate_info == experiment.replicate_info).all()
    assert experiment.picks.shape == (3, 5, len(experiment.members))


def test_the_report_section_writes_its_tables_and_figure(experiment, tmp_path):
    from pairplay.report.future_actions import action_level_section
    from pairplay.report.study import markdown_table
    drawn = []
    lines = action_level_section(tmp_path, experiment, markdown_table, lambda *args: drawn.append(args))
    text = "\n".join(lines)
    assert text.startswith("## Action-level profiles (future work 1)") and "![action-level merges]" in text
    profiles = (tmp_path / "action_profiles.csv").read_text().splitlines()
    merges = (tmp_path / "action_merges.csv").read_text().splitlines()
    assert len(profiles) == 1 + len(experiment.persona) and len(merges) == 1 + len(experiment.members)
    assert drawn[0][0] == "grouped_bars_with_spread" and drawn[0][4] == tmp_path / "action_merges.png"


def test_profile_actions_prints_both_extractions(tmp_path, capsys):
    from pairplay.cli.main import main
    from pairplay.core.policies import to_policy_file
    from pairplay.schemas.policy import write_policy
    rejected = {a: -1.0 for a in ALONE}
    policies, q = user_tables([UP_LEFT_WORDS, LEFT_UP_WORDS],
                              [{UP_LEFT_WORDS: 1.5, **rejected}, {LEFT_UP_WORDS: 1.6, **rejected}])
    q[:, S, EXACT] = 1.0  # the exact position alone works too
    for i in range(2):
        write_policy(tmp_path / f"p{i}.json", to_policy_file(q[i], np.zeros((N_STATES, 88), dtype=np.int64),
                                                             policies[i], algorithm="q-learning", participant="c"))
    assert main(["profile", str(tmp_path), "--actions"]) == 0
    out = capsys.readouterr().out
    assert "4.3 -> 0.0" in out and "TOP_LEFT_L0" in out and '"Maybe up" + turn left' in out
    other = q.copy()
    other[:, S, UP_LEFT_WORDS] = other[:, S, LEFT_UP_WORDS] = -1.0  # a second user who rejects both pairs
    other[:, S, EXACT] = 2.0
    other[1, S, UP_LEFT_WORDS] = -1.5  # (two policies of one user, not one policy twice: combine refuses that)
    greedy = policies.copy()
    greedy[:, S] = EXACT  # its greedy action is its Q-table's (a policy file's rule: schemas/policy.py)
    for i in range(2):
        write_policy(tmp_path / f"o{i}.json", to_policy_file(other[i], np.zeros((N_STATES, 88), dtype=np.int64),
                                                             greedy[i], algorithm="q-learning", participant="o"))
    target = tmp_path.parent / "merged.json"
    assert main(["combine", str(tmp_path), "--actions", "-o", str(target)]) == 0
    from pairplay.schemas.policy import read_policy
    merged = read_policy(target)
    assert merged.greedy[S] == EXACT and merged.rules[S].endswith("whole=chosen(2 of 2)")


def test_a_combined_policy_is_never_taken_as_a_users_policy(tmp_path, capsys):
    """Before (a new user's trial): a second `combine FOLDER -o FOLDER/m2.json` took the first's merged
    FOLDER/m.json as one more policy of a user (its profile said 3 policies of 2); now it is refused."""
    from pairplay.cli.main import main
    from pairplay.core.policies import to_policy_file
    from pairplay.schemas.policy import write_policy
    policies, q = user_tables([UP_LEFT_WORDS, LEFT_UP_WORDS], [{UP_LEFT_WORDS: 1.5}, {LEFT_UP_WORDS: 1.6}])
    for shift, name in enumerate(("a", "b")):
        for i in range(2):
            write_policy(tmp_path / f"{name}{i}.json", to_policy_file(
                q[i] + 0.1 * shift, np.zeros((N_STATES, 88), dtype=np.int64), policies[i], algorithm="q-learning", participant=name))
    assert main(["combine", str(tmp_path), "-o", str(tmp_path / "m.json")]) == 0
    capsys.readouterr()
    assert main(["combine", str(tmp_path), "-o", str(tmp_path / "m2.json")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is a combined policy" in err and "m.json" in err, err
    assert not (tmp_path / "m2.json").exists()
