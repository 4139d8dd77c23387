"""A key file belongs to one study (trial27 F8).

A new user's trial typed the README's `--key-file ~/private/keys.csv` again for a second study: `init` took
it, each study then listed the other's participants as "in the key file only: a crash cut its registration",
and `participant delete` told them to remove that line by hand: another study's only link from pseudonym to
person. Now `protocol init` refuses a key file that already holds lines, each line names its study (a third
cell), and every reader of the key file (the ids given, the "key file only" diagnosis, a deletion) reads only
its own study's lines; a line of two cells (an older pairplay's) is still the study's own.
"""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from pairplay.replay.studydata import StudyData, StudyDataError

STUDY = Path(__file__).parent / "data" / "pilot-study.toml"


def rows(path: Path) -> list[list[str]]:
    with open(path, encoding="utf-8", newline="") as f:
        return [r for r in csv.reader(f) if r]


def test_init_refuses_a_key_file_another_study_holds_lines_in(tmp_path, pairplay_cli):
    key = tmp_path / "private" / "keys.csv"
    first = StudyData.create(tmp_path / "robot", STUDY, key_file=key)
    first.register_many(first.study.phase[0].id, label="Ada Lovelace")
    run = pairplay_cli("protocol", "init", tmp_path / "k2", "--study", STUDY, "--key-file", key)
    assert run.returncode == 2, run
    assert "Traceback" not in run.stderr and len(run.stderr.strip().splitlines()) == 1, run.stderr
    assert "keys.csv" in run.stderr and "one study" in run.stderr, run.stderr
    assert not (tmp_path / "k2" / "journal.jsonl").exists()
    assert rows(key)[0][:2] == ["p01", "Ada Lovelace"]  # untouched


def test_two_studies_sharing_a_key_file_read_only_their_own_lines(tmp_path):
    """Two studies already sharing one (an empty key file taken by a second init, or made so by an older
    pairplay): neither calls the other's names crash leftovers, skips the other's ids, or erases its lines."""
    key = tmp_path / "private" / "keys.csv"
    robot = StudyData.create(tmp_path / "robot", STUDY, key_file=key)
    k2 = StudyData.create(tmp_path / "k2", STUDY, key_file=key)  # empty still: taken
    phase = robot.study.phase[0].id
    assert robot.register_many(phase, label="Ada Lovelace") == ["p01"]
    assert k2.register_many(phase, label="Bob Builder") == ["p01"]  # not p02: Ada is not k2's
    assert k2.register_many(phase, label="Dan") == ["p02"]
    robot, k2 = StudyData(tmp_path / "robot"), StudyData(tmp_path / "k2")
    assert robot.id_notes() == ({}, "") and k2.id_notes() == ({}, "")
    k2.delete_participant("p01")  # Bob's line goes, Ada's (robot's p01) stays
    assert [r[1] for r in rows(key)] == ["Ada Lovelace", "Dan"]
    assert StudyData(tmp_path / "robot").participant("p01")


def test_an_older_key_file_of_two_cells_is_still_the_studys_own(tmp_path):
    key = tmp_path / "private" / "keys.csv"
    data = StudyData.create(tmp_path / "s", STUDY, key_file=key)
    phase = data.study.phase[0].id
    data.register_many(phase, label="Carla")
    key.write_text("p01,Carla\np02,Dieter\n")  # an older pairplay's lines; p02's registration cut by a crash
    data = StudyData(tmp_path / "s")
    assert "p02" in data.id_notes()[0]
    assert data.register_many(phase, label="Eve") == ["p03"]
    with pytest.raises(StudyDataError, match="key file"):
        data.participant("p02")
    data.delete_participant("p01")
    assert [r[:2] for r in rows(key)] == [["p02", "Dieter"], rows(key)[1][:2]] and rows(key)[1][1] == "Eve"
