"""The study TOML (schemas/study.py): the shipped example is the thesis's protocol; mistakes are one line."""

from __future__ import annotations

import subprocess
import sys

import pytest

from pairplay.schemas.config import LearnerConfig
from pairplay.schemas.study import StudyFileError, example_text, load_study, parse_study


def test_the_shipped_example_is_the_thesis_protocol():
    s = parse_study(example_text())
    p1, p2 = s.phase
    assert (p1.games, p1.rounds, p1.algorithm, p1.players) == (2, 5, "q-learning", "new")
    assert (p2.games, p2.rounds, p2.algorithm, p2.players, p2.bias) == (1, 5, "pi-reuse", "all", "phase1")
    c1, c2 = s.learner_config(p1), s.learner_config(p2)
    assert c1 == LearnerConfig.human_phase1(5)
    # epsilon 0.9 falling by a fifth of 0.9 each round (7.2)
    assert [round(max(c1.epsilon_min, c1.epsilon_start - c1.epsilon_step * r), 9) for r in range(5)] == \
        [0.9, 0.72, 0.54, 0.36, 0.18]
    assert c2.reuse_rounds == 4  # the last round on the new policy alone
    assert s.study.ignore_window_ms == 1500
    kinds = {i.kind for i in s.questionnaire["after-game"].item}
    assert kinds == {"likert", "text", "choice"}
    returning = {i.id for i in s.questions("after-game", True)}
    new = {i.id for i in s.questions("after-game", False)}
    assert "best-round" in returning - new and "robots-before" in new - returning


BASE = example_text()


@pytest.mark.parametrize("change,where", [
    (("rounds = 5", "rounds = \"five\"", 1), '[[phase]] "phase1" rounds: must be an integer, got "five"'),
    (("rounds = 5", "rounds = 0", 1), '[[phase]] "phase1" rounds: must be 1..100, got 0'),
    (("games = 2", "games = 2\ncolour = 3", 1), '[[phase]] "phase1" colour: [[phase]] has no key `colour`; its keys: algorithm, bias,'),
    # a misspelt key: the key it resembles
    (("rounds = 5", "rouns = 5", 1), '[[phase]] "phase1" rouns: [[phase]] has no key `rouns` (did you mean `rounds`?)'),
    # a table where none is taken: named by its header, with the keys its table takes (it was msgspec's
    # "study: Object contains unknown field `grid`")
    (("seed = 0", "seed = 0\n[study.grid]\nx = 1", 1), "s.toml: [study.grid]: [study] has no table `grid`; its keys: consent_form, id, "),
    (("bias = \"phase1\"", "bias = \"phase3\"", 1), '[[phase]] "phase2" bias: "phase3" is not an earlier phase (earlier: phase1)'),
    (("questionnaires = [\"after-game\"]", "questionnaires = [\"exit\"]", 1), '[[phase]] "phase1" questionnaires: no [questionnaire.exit] in the file'),
    (("scale = 5", "scale = 40", 1), '[[questionnaire.after-game.item]] "followed" scale: a Likert scale has 2..11 points, got 40'),
    (("id = \"avoided-wrong\"", "id = \"followed\"", 1), '[[questionnaire.after-game.item]] #2 id: "followed" is used twice'),
    (("id = \"thesis-ch7\"", "id = \"My Study\"", 1), '[study] id: "My Study" must be 1-40'),
    (("robot = \"virtual\"", "robot = \"telepathy\"", 1), "[study] robot: 'telepathy': unknown backend"),
    # a robot URL the session's --robot refuses (no host, a bad port) passed check and init, then the
    # study's first game crashed with a traceback (a new user's trial): the study file uses that parser
    (("robot = \"virtual\"", "robot = \"furhat://\"", 1), "[study] robot: 'furhat://': needs a host"),
    (("robot = \"virtual\"", "robot = \"iristk://\"", 1), "[study] robot: 'iristk://': needs a host"),
    (("robot = \"virtual\"", "robot = \"furhat://h:99999\"", 1), "[study] robot: 'furhat://h:99999': bad port"),
    (("robot = \"virtual\"", "robot = \"furhat://h:abc\"", 1), "[study] robot: 'furhat://h:abc': bad port"),
    (("robot = \"virtual\"", "robot = \"furhat://h?colour=red\"", 1), "unknown parameter 'colour'"),
    # a learner override of the wrong type passed check and failed when the game's session read it back
    (("preset = \"human-phase1\"", "preset = \"human-phase1\"\nlearner = { epsilon_every = 1.5 }", 1),
     '[[phase]] "phase1" learner.epsilon_every: must be an integer, got 1.5'),
    (("kind = \"likert\"", "kind = \"slider\"", 1), '[[questionnaire.after-game.item]] "followed" kind: must be one of likert, text, choice, got "slider"'),
    # msgspec's "Expected `int`, got `float`" in the words the sweep file uses (a trial)
    (("rounds = 5", "rounds = 1e3", 1), '[[phase]] "phase1" rounds: must be an integer, got 1e3'),
    # a number as the file has it (tomllib has no hook for integers: `1_000` was said "1000")
    (("rounds = 5", "rounds = 1_000", 1), '[[phase]] "phase1" rounds: must be 1..100, got 1_000'),
    (("rounds = 5", "rounds = 20.0", 1), '[[phase]] "phase1" rounds: must be an integer, got 20.0'),
    (("scale = 5", "scale = 0x10", 1), '"followed" scale: a Likert scale has 2..11 points, got 0x10'),
    (("preset = \"human-phase1\"", "preset = \"human-phase1\"\nlearner = { epsilon_jump = 1 }", 1),
     '[[phase]] "phase1" learner.epsilon_jump: [phase.learner] has no key `epsilon_jump`'),
    (("algorithm = \"pi-reuse\"", "algorithm = \"q-learning\"", 1), '[[phase]] "phase2" bias: only a pi-reuse phase uses a bias policy'),
    # a bias phase of one game a participant: no profile (algorithm 3 compares a participant's policies); the
    # combiner merged each as perceiving every channel (thesis 7.2: 2 games are "the minimum required")
    (("games = 2", "games = 1", 1), '[[phase]] "phase2" bias: phase "phase1" plays 1 game per participant; a bias phase needs 2 or more'),
    (("[study]", "[study", 1), "not valid TOML"),
    # a pi-reuse phase that never reuses (its one round under human-phase2 is the last, on the new policy
    # alone; psi 0) was accepted: Q-learning, called pi-reuse in the journal and the report
    (("rounds = 5\nalgorithm = \"pi-reuse\"", "rounds = 1\nalgorithm = \"pi-reuse\"", 1),
     '[[phase]] "phase2": a pi-reuse phase of 1 round that never reuses the bias policy'),
    (("preset = \"human-phase2\"", "preset = \"human-phase2\"\nlearner = { psi_start = 0.0 }", 1),
     '[[phase]] "phase2": a pi-reuse phase of 5 rounds that never reuses the bias policy: its psi starts at 0'),
])
def test_a_mistake_is_one_line_naming_the_place(change, where):
    old, new, count = change
    assert old in BASE
    with pytest.raises(StudyFileError) as err:
        parse_study(BASE.replace(old, new, count), "s.toml")
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith("s.toml: ") and where in msg, msg
    if "not valid TOML" not in msg:  # (tomllib's own words, with its line)
        assert "phase[" not in msg and "Expected" not in msg and "Object" not in msg and "$." not in msg, msg


def test_the_cli_check_prints_the_protocol_or_one_line(tmp_path):
    ok = subprocess.run([sys.executable, "-m", "pairplay.cli.main", "protocol", "check", "thesis-ch7"],
                        capture_output=True, text=True)
    assert ok.returncode == 0 and "phase2" in ok.stdout and "pi-reuse" in ok.stdout
    bad = tmp_path / "bad.toml"
    bad.write_text(BASE.replace("games = 2", "games = -1"))
    out = subprocess.run([sys.executable, "-m", "pairplay.cli.main", "protocol", "check", str(bad)],
                         capture_output=True, text=True)
    assert out.returncode == 2 and out.stdout == ""
    assert out.stderr.count("\n") == 1 and '[[phase]] "phase1" games: must be 1..20, got -1' in out.stderr and "Traceback" not in out.stderr
    missing = subprocess.run([sys.executable, "-m", "pairplay.cli.main", "protocol", "check", str(tmp_path / "no")],
                             capture_output=True, text=True)
    assert missing.returncode == 2 and missing.stderr.count("\n") == 1


def test_load_study_reports_an_unreadable_file(tmp_path):
    (tmp_path / "s.toml").write_bytes(b"\xff\xfe bad")
    with pytest.raises(StudyFileError, match="cannot read"):
        load_study(tmp_path / "s.toml")


@pytest.mark.parametrize("url", ["virtual", "none", "virtual?time_scale=0.1", "furhat://192.0.2.10",
                                 "iristk://robot.local:1932?ticket=lab", "furhat://h:9000?key=k&gestures=furhat"])
def test_a_robot_url_a_session_takes_is_taken_by_the_study_file(url):
    parse_study(BASE.replace('robot = "virtual"', f'robot = "{url}"', 1), "s.toml")


@pytest.mark.parametrize("learner, field", [('{ alpha_start = "x" }', '[[phase]] "phase1" learner.alpha_start'),
                                            ('{ epsilon_start = 0.5, alpha_start = [1] }',
                                             '[[phase]] "phase1" learner.alpha_start')])
def test_a_learner_setting_of_the_wrong_type_names_its_field(learner, field):
    """msgspec says a table's value at `learner[...]`: the line named the table, not the field."""
    text = example_text().replace('players = "new"\n', f'players = "new"\nlearner = {learner}\n', 1)
    with pytest.raises(StudyFileError) as err:
        parse_study(text, "s.toml")
    assert str(err.value).startswith(f"s.toml: {field}: must be a number, got "), str(err.value)


PHASE1_KEYS = 'players = "new"\nquestionnaires = ["after-game"]'
PHASE_REST = 'algorithm = "q-learning"\npreset = "human-phase1"\n' + PHASE1_KEYS


@pytest.mark.parametrize("old,new,said", [
    # a new user's trial: [phase.learner] written before the phase's last keys took them into the learner
    (PHASE1_KEYS, 'players = "new"\n[phase.learner]\nepsilon_start = 0.5\nquestionnaires = ["after-game"]',
     '[phase.learner] of "phase1" questionnaires: `questionnaires` belongs to [[phase]], not to [phase.learner]: the keys '
     "after a [phase.learner] line are that table's; move `questionnaires = ...` above that line"),
    ("games = 2\nrounds = 5\n" + PHASE_REST, PHASE_REST + "\n[phase.learner]\nepsilon_start = 0.5\ngames = 2\nrounds = 5",
     '[phase.learner] of "phase1" games: `games` belongs to [[phase]], not to [phase.learner]'),
    ('preset = "human-phase1"\n', '[phase.learner]\nepsilon_start = 0.5\npreset = "human-phase1"\n',
     '[phase.learner] of "phase1" preset: `preset` belongs to [[phase]], not to [phase.learner]'),
    # a key of one table written in another
    ("[study]\n", "[study]\n[study.learner]\nalpha_start = 0.3\n",
     "[study.learner]: [study] has no key `learner`; `learner` is a key of [[phase]]"),
    ("[study]\n", "[study]\nrounds = 3\n", "[study] rounds: [study] has no key `rounds`; `rounds` is a key of [[phase]]"),
    # a new user's trial: a table's key written above the file's first [table] line (it was msgspec's
    # "Object contains unknown field `robot`")
    ('robot = "virtual"\n', "", None),
    ("[study]\n", "seed = 3\n[study]\n", "seed: `seed` belongs to [study], not at the top of the file (above its "
     "first [table] line): move `seed = ...` below the [study] line"),
    ("[study]\n", "games = 3\n[study]\n", "games: `games` belongs to [[phase]], not at the top of the file"),
    ("[study]\n", 'text = "x"\n[study]\n', "text: `text` belongs to [[questionnaire.NAME.item]], not at the top"),
    # a table where a value was expected
    ("seed = 0\n", "[study.seed]\nvalue = 0\n",
     "[study.seed]: [study.seed] is a table, where `seed` takes a value: write `seed = ...` among the keys of [study]"),
    (PHASE1_KEYS, PHASE1_KEYS + "\n[phase.learner.epsilon_start]\nx = 1",
     '[phase.learner.epsilon_start] of "phase1": [phase.learner.epsilon_start] is a table'
     ", where `epsilon_start` takes a "
     "value: write `epsilon_start = ...` among the keys of [phase.learner]"),
    ('title = "About the game you just played"\n', '[questionnaire.after-game.title]\ntext = "x"\n',
     "[questionnaire.after-game.title]: [questionnaire.after-game.title] is a table, where `title` takes a value"),
])
def test_a_table_or_key_at_the_wrong_level_says_where_it_belongs(old, new, said):
    assert old in BASE
    text = BASE.replace(old, new, 1)
    if said is None:  # the robot above [study]: the trial's own file
        text, said = old + text, ("robot: `robot` belongs to [study], not at the top of the file (above its first "
                                  "[table] line): move `robot = ...` below the [study] line")
    with pytest.raises(StudyFileError) as info:
        parse_study(text, "s.toml")
    line = str(info.value)
    assert line.startswith("s.toml: ") and "\n" not in line and said in line, line
    assert "Expected" not in line and "got `" not in line, line


@pytest.mark.parametrize("typed", ["1e7", "6.0e41", "60_001.0"])
def test_a_number_of_the_study_file_is_echoed_as_the_file_has_it(typed):
    """A trial: `ignore_window_ms = 1e7` was said "got 10000000": the number as parsed, not as written."""
    with pytest.raises(StudyFileError) as info:
        parse_study(BASE.replace("ignore_window_ms = 1500", f"ignore_window_ms = {typed}", 1), "s.toml")
    assert str(info.value) == f"s.toml: [study] ignore_window_ms: must be 0..60000 (ms), got {typed}", info.value
