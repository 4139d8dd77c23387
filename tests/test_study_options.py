"""Study and sweep settings a researcher gets wrong are refused up front, as one kind (StudySettings.check).

Before: `pairplay study --rounds 1` (2, 5, 9) ended in a traceback in core/study.py (the speed-up takes a
greedy snapshot every 10 rounds: none, an array of size 0); `--personas ' '` in another (no array to
stack); `--personas deaf,deaf` said a *temporary* policy file existed; `--rounds 10 --reuse-last 50`
ran a pi-reuse arm that never reused and a report of the "first 50 rounds" of 10; a sweep with
`reuse = true` and `rounds = [5, 20]` ran until the 5 failed (exit 1, nothing kept), one with
`personas = " "` left cells/ and grid.toml behind, one with "blind,blind" exited 0. And the report's
"Re-run:" line dropped every option but four, so it printed another study's command.
Now: exit 2, ONE line naming the option (or grid key) and its range, nothing written.
"""

from __future__ import annotations

import argparse
import shlex

import pytest

from pairplay.cli import study as study_verb
from pairplay.cli.main import main
from pairplay.report.study import SettingError, StudySettings, first_rounds_text

STUDY_MISTAKES = [
    (["--rounds", "1"], "--rounds: must be at least 10"),
    (["--rounds", "2"], "--rounds: must be at least 10"),
    (["--rounds", "5"], "--rounds: must be at least 10"),
    (["--rounds", "9", "--reuse-last", "2"], "--rounds: must be at least 10"),
    (["--personas", " "], "--personas: names no persona"),
    (["--personas", ""], "--personas: names no persona"),
    (["--personas", ", ,"], "--personas: ', ,' has an empty item (item 1 of 3)"),
    (["--personas", "deaf,,blind"], "--personas: 'deaf,,blind' has an empty item (item 2 of 3)"),
    (["--personas", "deaf,deaf"], "--personas: names deaf twice"),
    (["--personas", "deaf,Deaf"], "--personas: names deaf twice"),
    (["--rounds", "10", "--reuse-last", "50"], "--reuse-last: must be below --rounds 10"),
    (["--rounds", "60", "--reuse-last", "60"], "--reuse-last: must be below --rounds 60"),
    (["--personas", "nobody"], "--personas: unknown persona 'nobody'"),
    (["--psi", "0"], "--psi: must be above 0 when the speed-up runs"),  # its pi-reuse arm was Q-learning
    (["--games", "99999999999999999999"], "--games: must be 1..9223372036853775808"),
    (["--reuse-seeds", str(2**63)], "--reuse-seeds: must be 1..9223372036853775808"),
    (["--personas", "blind", "--algorithm", "lspi", "--rounds", "9"], "--rounds: must be at least 10 with --algorithm lspi"),
    # LSPI's settings with Q-learning ran Q-learning without a word (session refused them): session's rule
    (["--lspi-ridge", "2"], "--algorithm: --lspi-ridge needs --algorithm lspi, not q-learning"),
    # a trial: the speed-up's settings where it does not run were ignored, exit 0 (as LSPI's were)
    (["--personas", "blind", "--psi", "0.3", "--reuse-last", "2"],
     "--psi: --psi/--reuse-last set the speed-up experiment (pi-reuse), which does not run here: it needs 2+ "
     "personas without --train-only"),
    (["--train-only", "--psi-decay", "0.3"], "--psi-decay: --psi-decay set the speed-up experiment"),
    (["--lspi-every", "3", "--lspi-ridge", "1"], "--lspi-ridge/--lspi-every need --algorithm lspi, not q-learning"),
]


@pytest.mark.parametrize("argv,needle", STUDY_MISTAKES)
def test_a_study_that_cannot_run_as_asked_is_refused_in_one_line(argv, needle, tmp_path, capsys):
    out = tmp_path / "study"
    for force in ([], ["--force"]):  # --force changes nothing: the mistake is the option's
        assert main(["study", "--quiet", *argv, "--out", str(out), *force]) == 2
        err = capsys.readouterr().err
        assert needle in err and err.count("\n") == 1 and "Traceback" not in err, err
    assert not out.exists() and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("rounds,reuse_last", [(10, 2), (20, 5), (50, 12), (51, 50), (500, 50)])
def test_a_short_study_without_reuse_last_gets_a_default_that_fits(rounds, reuse_last):
    """`pairplay study --personas ashley,helmut --rounds 20` was refused for the default --reuse-last 50,
    an option the user never gave (a new user's trial): not given, it is a quarter of a study of 50
    rounds or fewer, and 50 otherwise; the Re-run line states it when it is not 50."""
    import argparse
    p = argparse.ArgumentParser()
    study_verb.add_arguments(p)
    args = p.parse_args(["--personas", "ashley,helmut", "--rounds", str(rounds)])
    settings = study_verb.settings_of(args)
    assert settings.reuse_last == reuse_last
    assert (f"--reuse-last {reuse_last}" in settings.rerun_command()) == (reuse_last != 50)


@pytest.mark.parametrize("where", ["[study]\nrounds = 20\n", "[grid]\nrounds = [20, 60]\n"])
def test_a_short_sweep_without_reuse_last_gets_the_studys_default(where, tmp_path):
    """A sweep of `rounds = 20` with `reuse = true` and no reuse_last was refused for the default 50, which
    `pairplay study --rounds 20` no longer is: a cell's reuse_last not given is the study's
    default_reuse_last of its own rounds (one helper for the verb and the sweep); one given is kept."""
    from pairplay.report.sweep import read_grid
    path = tmp_path / "grid.toml"
    head = 'reuse = true\nseeds = 1\n[study]\npersonas = "blind,deaf"\n'
    path.write_text(head + where.replace("[study]\n", ""))
    grid = read_grid(path)
    got = {s.rounds: s.reuse_last for s in map(grid.study_settings, grid.cells())}
    assert got == ({20: 5} if "[study]" in where else {20: 5, 60: 50})
    path.write_text(head + "reuse_last = 3\n" + where.replace("[study]\n", ""))
    assert {s.reuse_last for s in map(read_grid(path).study_settings, read_grid(path).cells())} == {3}


def test_what_the_speed_up_needs_binds_only_when_it_runs():
    # one persona, or --train-only: no speed-up, so no snapshot interval and no pi-reuse window
    StudySettings(personas="blind", rounds=1).check()
    StudySettings(personas="blind,deaf", rounds=1, train_only=True).check()
    with pytest.raises(SettingError) as info:
        StudySettings(personas="blind", rounds=5).check(speed_up=True)  # a sweep's reuse = true
    assert info.value.key == "rounds"


def test_run_study_refuses_what_the_verb_refuses(tmp_path):
    from pairplay.report.study import run_study
    with pytest.raises(SettingError, match="names blind twice"):
        run_study(StudySettings(personas="blind,blind", rounds=1, train_only=True), tmp_path / "s")
    assert not (tmp_path / "s").exists()


def test_a_short_games_early_measure_says_it_is_all_its_rounds():
    assert first_rounds_text(500) == first_rounds_text(50) == "first 50 rounds"
    assert first_rounds_text(20) == "first 20 rounds (all)"


def _parse(line: str) -> StudySettings:
    """A printed `pairplay study ...` line through the study's own parser, as the config it makes."""
    words = shlex.split(line)
    assert words[:2] == ["pairplay", "study"]
    p = argparse.ArgumentParser()
    study_verb.add_arguments(p)
    args = p.parse_args(words[2:])
    return study_verb.settings_of(args)  # the verb's own options -> settings (its defaults included)


@pytest.mark.parametrize("changes", [
    {},
    dict(personas="blind,deaf,tatiana", games=2, rounds=60, eval_rounds=5, reuse_seeds=2, reuse_last=10),
    dict(seed=2**64 - 1, psi=0.5, psi_decay=0.875, trained_updates=0, reward_bonus="match"),
    dict(algorithm="lspi", lspi_ridge=0.1, lspi_every=3, personas="wasim, frances"),
    dict(psi=0.1 + 0.2, psi_decay=1.0 / 3),  # floats that print long: their repr round-trips
    dict(train_only=True, games=3),  # (the speed-up's settings are refused with it: they would be ignored)
])
def test_the_rerun_line_parses_back_to_the_same_study(changes):
    settings = StudySettings(**changes)
    line = settings.rerun_command()
    assert _parse(line) == settings, line
    for key in changes:  # every option that differs from the default is on the line
        assert "--" + key.replace("_", "-") in line


def test_every_study_setting_is_an_option_of_the_verb():
    p = argparse.ArgumentParser()
    study_verb.add_arguments(p)
    dests = {a.dest for a in p._actions}
    assert set(StudySettings.__dataclass_fields__) <= dests


GRID_MISTAKES = [
    ('reuse = true\nseeds = 1\n[study]\npersonas = "blind,deaf"\ngames = 1\neval_rounds = 2\nreuse_seeds = 1\n'
     'reuse_last = 2\n[grid]\nrounds = [20, 5]\n', "rounds = 5: must be at least 10"),
    ('seeds = 1\n[study]\npersonas = " "\n', '[study] personas = " ": names no persona'),
    ('seeds = 1\n[grid]\npersonas = ["blind", ""]\n', '[grid] personas = "": names no persona'),
    ('seeds = 1\n[study]\npersonas = "blind,blind"\n', '[study] personas = "blind,blind": names blind twice'),
    ('seeds = 1\n[grid]\npersonas = ["blind", "blind,,deaf"]\n', '[grid] personas = "blind,,deaf": \'blind,,deaf\' has an empty item'),
    ('reuse = true\nseeds = 1\n[study]\npersonas = "blind,deaf"\nrounds = 20\nreuse_last = 50\n',
     "reuse_last = 50: must be below rounds 20"),
    ('seeds = [1, 99999999999999999999]\n[study]\npersonas = "blind"\n', "seeds 0..18446744073709551615"),
    ('seeds = [1, 1]\n[study]\npersonas = "blind"\n', "repeats a seed"),
    ('reuse = "no"\n[study]\npersonas = "blind"\n', "must be true or false"),
    ('reuse = true\nseeds = 1\n[study]\npersonas = "blind,deaf"\n[grid]\npsi = [0.5, 1.5]\n',
     "psi = 1.5: must be between 0 and 1"),
    ('reuse = true\nseeds = 1\n[study]\npersonas = "blind,deaf"\n[grid]\npsi = [0.5, 0.0]\n',
     "psi = 0.0: must be above 0 when the speed-up runs"),  # 0.0 as the file has it (pairplay/numbers.py)
    ('[study]\nalgorithm = "sarsa"\n', '[study] algorithm = "sarsa": must be one of q-learning, lspi, got "sarsa"'),
    ('[study]\nreward_bonus = "always"\n', '[study] reward_bonus = "always": must be one of correct, consistent, match'),
    # LSPI's settings in a cell that learns by Q-learning, which ignored them (the study's and session's rule)
    ('seeds = 1\n[study]\nlspi_ridge = 2\n', "algorithm = 'q-learning' (the study's default): lspi_ridge needs algorithm lspi, not q-learning"),
    # a trial: a grid of the speed-up's settings without `reuse = true` gave cells alike, exit 0
    ('seeds = 1\n[study]\npersonas = "blind,deaf"\n[grid]\npsi_decay = [0.5, 0.99]\n',
     "psi_decay = 0.5: psi_decay set the speed-up experiment (pi-reuse), which does not run here: it needs reuse = true"),
    ('seeds = 1\n[grid]\nalgorithm = ["lspi", "q-learning"]\nlspi_every = [3, 10]\n',
     'lspi_every needs algorithm lspi, not q-learning (cell algorithm = "q-learning", lspi_every = 3)'),
]


def test_a_folder_given_as_the_sweep_file_is_one_clear_line(tmp_path, capsys):
    (tmp_path / "bad").mkdir()  # a trial: `pairplay sweep bad` said `Is a directory (bad)`
    assert main(["sweep", "--quiet", str(tmp_path / "bad"), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err == f"pairplay sweep: {tmp_path / 'bad'}: a folder, not a sweep file: give the grid's TOML file\n", err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("text,needle", GRID_MISTAKES)
def test_a_sweep_checks_every_cell_before_it_writes_anything(text, needle, tmp_path, capsys):
    grid = tmp_path / "grid.toml"
    grid.write_text(text)
    out = tmp_path / "out" / "sweep"
    assert main(["sweep", "--quiet", str(grid), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1 and "Traceback" not in err, err
    assert not (tmp_path / "out").exists()


def test_a_number_is_echoed_as_it_was_given_and_a_type_is_named_in_words(tmp_path, capsys):
    """A new user's trial: `--psi 0` was said back as "got 0.0" (options and TOML integers become floats
    on the way in: pairplay/numbers.py `shown`), and the sweep said "is not a int". Every refusal of a
    setting, a study file's value and a sweep's grid echoes the number as given."""
    from pairplay.report.sweep import GridError, read_grid
    from pairplay.schemas.study import StudyFileError, example_text, parse_study

    assert main(["study", "--personas", "blind,tatiana", "--games", "1", "--rounds", "10", "--psi", "0",
                 "--out", str(tmp_path / "s")]) == 2
    err = capsys.readouterr().err
    assert err.rstrip().endswith("got 0") and "0.0" not in err, err
    for old, new, said in (
            ('players = "new"\n', 'players = "new"\nlearner = { epsilon_start = 2 }\n', "got 2"),
            ("ignore_window_ms = 1500", "ignore_window_ms = 100000", "got 100000")):
        text = example_text().replace(old, new, 1)
        with pytest.raises(StudyFileError) as info:
            parse_study(text, "s.toml")
        assert str(info.value).endswith(said) and f"{said}.0" not in str(info.value), info.value
    grids = {"[grid]\ngames = ['two']": "must be an integer, got 'two'", "[grid]\npsi = [2]": "got 2",
             "[grid]\nseed_count = 1\n": "is not a", "[grid]\nrounds = [3.5]": "must be an integer, got 3.5"}
    for text, said in list(grids.items())[:2] + [list(grids.items())[3]]:
        (tmp_path / "g.toml").write_text(text)
        with pytest.raises(GridError) as info:
            read_grid(tmp_path / "g.toml").cells() if "psi" in text else read_grid(tmp_path / "g.toml")
        assert said in str(info.value) and " a int" not in str(info.value) and "2.0" not in str(info.value), info.value
