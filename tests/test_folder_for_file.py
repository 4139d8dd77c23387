"""A folder given where a file is expected, and a file where a folder is, is said in the usual `what (where)`
form with what was expected there (a new user's trial): `protocol check STUDY_FOLDER` said the system's
"cannot read: Is a directory", `combine STUDY_FOLDER` read the folder's settings.json as a policy file ("no
"format" field") with no hint, `report STUDY.toml` said "cannot write there". A study folder stands for its
study file where a study file is asked for (schemas/study.py `study_file_of`); every JSON or TOML input says
a folder alike (schemas/jsonfile.py `a_folder`)."""

from __future__ import annotations

import pytest


@pytest.fixture
def study(pairplay_cli, tmp_path):
    folder = tmp_path / "s"
    assert pairplay_cli("protocol", "init", folder, "--study", "thesis-ch7", "-q").returncode == 0
    (tmp_path / "empty").mkdir()
    (tmp_path / "s.toml").write_text((folder / "study.toml").read_text())
    return folder


def test_a_study_folder_checked_is_its_study_file(pairplay_cli, study):
    r = pairplay_cli("protocol", "check", study)
    assert r.returncode == 0 and "study thesis-ch7:" in r.stdout, r


def test_a_study_folder_as_the_study_of_a_new_one(pairplay_cli, study, tmp_path):
    r = pairplay_cli("protocol", "init", tmp_path / "new", "--study", study, "-q")
    assert r.returncode == 0, r
    assert (tmp_path / "new" / "study.toml").read_text() == (study / "study.toml").read_text()
    assert (study / "study.toml").is_file()  # the study's own is kept


@pytest.mark.parametrize("args, said", [
    (["protocol", "check", "{empty}"], "{empty}: a folder, not a study file: give a study's TOML file or a study folder"),
    (["protocol", "init", "{tmp}/n", "--study", "{empty}"], "{empty}: a folder, not a study file"),
    (["protocol", "init", "{tmp}/n", "--study", "thesis-ch7", "--key-file", "{empty}"],
     "a folder, not a key file: give the path of a CSV file"),
    (["report", "{study}", "--reference", "{empty}"], "{empty}: a folder, not a policy file"),
    (["session", "--participant", "sim:blind", "--algorithm", "fixed", "--policy", "{empty}"],
     "{empty}: a folder, not a policy file"),
    (["robot", "--try", "3", "--robot-config", "{empty}"], "{empty}: a folder, not a robot config"),
    (["robot", "--try", "3", "--calibration", "{empty}"], "{empty}: a folder, not a calibration file"),
    (["router", "--zenoh-config", "{empty}"], "{empty}: a folder, not a Zenoh config"),
    (["combine", "{study}", "-o", "{tmp}/m.json"], "a study folder, not policy files: give its games' policies, "
                                                   "{study}/policies"),
    (["profile", "{study}"], "a study folder, not policy files"),
    (["report", "{tmp}/s.toml"], "{tmp}/s.toml: a file, not a study folder: `pairplay protocol init FOLDER --study"),
    (["protocol", "status", "{tmp}/s.toml"], "{tmp}/s.toml: a file, not a study folder"),
])
def test_a_folder_for_a_file_or_a_file_for_a_folder_says_what_was_expected(pairplay_cli, study, tmp_path, args, said):
    names = {"{empty}": str(tmp_path / "empty"), "{study}": str(study), "{tmp}": str(tmp_path)}

    def filled(text: str) -> str:
        for k, v in names.items():
            text = text.replace(k, v)
        return text

    r = pairplay_cli(*[filled(a) for a in args], cwd=tmp_path, timeout=60)
    assert r.returncode == 2, r
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and filled(said) in lines[0] and "Is a directory" not in lines[0], lines
