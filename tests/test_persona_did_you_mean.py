"""A misspelt persona is refused with the one it resembles (a new user's trial).

`pairplay study --personas ashly` said "unknown persona 'ashly'; known: ashley, ..." and no hint, unlike a
misspelt key of every file (pairplay/nearest.py, one measure for all). Every verb that takes a persona's
name reads it through core/personas.py `persona`, so one place says it: `study --personas`, `protocol
pilot --personas`, `session --participant sim:NAME`.
"""

from __future__ import annotations

import pytest


@pytest.mark.parametrize("args", [
    ["study", "--personas", "blind,ashly", "--games", "1", "--rounds", "1"],
    ["session", "--participant", "sim:ashly", "--rounds", "1"],
])
def test_a_misspelt_persona_names_the_one_it_resembles(pairplay_cli, tmp_path, args):
    r = pairplay_cli(*args, "--out", tmp_path / "out", cwd=tmp_path)
    assert r.returncode == 2 and r.stdout == "", r
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "unknown persona 'ashly' (did you mean 'ashley'?); known: ashley, " in lines[0], lines


def test_a_name_like_none_has_no_hint_and_the_list(pairplay_cli, tmp_path):
    r = pairplay_cli("study", "--personas", "nobody", "--out", tmp_path / "out", cwd=tmp_path)
    assert r.returncode == 2 and "unknown persona 'nobody'; known: ashley, " in r.stderr and "did you mean" not in r.stderr


@pytest.fixture
def study_of_two(pairplay_cli, tmp_path):
    """A study folder (the bundled thesis-ch7) with p01 and p02 registered."""
    folder = tmp_path / "s"
    assert pairplay_cli("protocol", "init", folder, "--study", "thesis-ch7", "-q").returncode == 0
    for _ in range(2):
        assert pairplay_cli("protocol", "register", folder).returncode == 0
    return folder


@pytest.mark.parametrize("args, option, said", [
    (["protocol", "pilot", "{f}", "--personas", "ashly,blind"], "--personas",
     "unknown persona 'ashly' (did you mean 'ashley'?); known: ashley, "),
    (["protocol", "serve", "{f}", "--pilot", "p01=ashly"], "--pilot", "unknown persona 'ashly' (did you mean 'ashley'?)"),
    (["protocol", "serve", "{f}", "--pilot", "p01"], "--pilot", "'p01' is not ID=PERSONA"),
    (["protocol", "serve", "{f}", "--pilot", "p09=blind"], "--pilot", "no participant 'p09'"),
])
def test_a_refused_option_value_names_the_option(pairplay_cli, study_of_two, args, option, said):
    """protocol pilot --personas and serve --pilot said "unknown persona 'ashly' ..." (and `--pilot p01`
    "unknown persona ''") without the option that held it, unlike study --personas and session --participant."""
    r = pairplay_cli(*[str(study_of_two) if a == "{f}" else a for a in args])
    assert r.returncode == 2 and r.stdout == "", r
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and said in lines[0] and lines[0].endswith(f"({option})"), lines


@pytest.mark.parametrize("args, said", [
    (["session", "--participant", "sim:blind", "--preset", "human-phse1"],
     "argument --preset: invalid choice: 'human-phse1' (did you mean 'human-phase1'?)"),
    (["session", "--participant", "sim:blind", "--algorithm", "q-lerning"], "(did you mean 'q-learning'?)"),
    (["study", "--algorithm", "lsp"], "(did you mean 'lspi'?)"),
    (["protocol", "chek"], "invalid choice: 'chek' (did you mean 'check'?)"),
])
def test_a_misspelt_choice_names_the_one_it_resembles(pairplay_cli, tmp_path, args, said):
    """argparse's invalid choice listed the choices but, unlike every other refusal of a name, no hint."""
    r = pairplay_cli(*args, cwd=tmp_path)
    assert r.returncode == 2 and said in r.stderr and "choose from" in r.stderr, r.stderr


def test_a_choice_of_a_numbered_kind_has_no_hint(pairplay_cli, tmp_path):
    """`human-phase3` is another phase's preset, not a misspelling (pairplay/nearest.py): the list says it."""
    r = pairplay_cli("session", "--participant", "sim:blind", "--preset", "human-phase3", cwd=tmp_path)
    assert r.returncode == 2 and "did you mean" not in r.stderr and "choose from" in r.stderr, r.stderr


@pytest.mark.parametrize("line, said", [
    ('preset = "human-phase1"', '[[phase]] "phase1" preset: must be one of virtual, human-phase1, human-phase2, '
                                'got "human-phse1" (did you mean \'human-phase1\'?)'),
    ('algorithm = "q-learning"', "(did you mean 'q-learning'?)"),
])
def test_a_misspelt_value_of_a_study_file_names_the_one_it_resembles(pairplay_cli, tmp_path, line, said):
    from pairplay.schemas.study import example_text
    text = example_text()
    assert line in text
    wrong = line.replace("human-phase1", "human-phse1").replace("q-learning", "q-lerning")
    (tmp_path / "s.toml").write_text(text.replace(line, wrong, 1))
    r = pairplay_cli("protocol", "check", tmp_path / "s.toml")
    assert r.returncode == 2 and said in r.stderr, r.stderr


def test_init_names_the_study_option_it_refuses(pairplay_cli, tmp_path):
    r = pairplay_cli("protocol", "init", tmp_path / "s", "--study", "thesis-c7", cwd=tmp_path)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1, r
    assert "thesis-c7: no such study file, nor a bundled study (did you mean 'thesis-ch7'?)" in lines[0], lines
    assert lines[0].endswith("(--study)"), lines
