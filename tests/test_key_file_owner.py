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
import json
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
    assert rows(key)[1][:2] == ["p01", "Ada Lovelace"] and len(rows(key)) == 2  # untouched (after its header)


def test_two_studies_sharing_a_key_file_read_only_their_own_lines(tmp_path):
    """Two studies already sharing one (an empty key file taken by a second init, or made so by an older
    pairplay): neither calls the other's names crash leftovers, skips the other's ids, or erases its lines."""
    key = tmp_path / "private" / "keys.csv"
    robot = StudyData.create(tmp_path / "robot", STUDY, key_file=key)
    StudyData.create(tmp_path / "k2", STUDY)  # sharing it (init refuses that now: a settings.json edited by hand)
    (tmp_path / "k2" / "settings.json").write_text(json.dumps({"key_file": str(key)}))
    k2 = StudyData(tmp_path / "k2")
    phase = robot.study.phase[0].id
    assert robot.register_many(phase, label="Ada Lovelace") == ["p01"]
    assert k2.register_many(phase, label="Bob Builder") == ["p01"]  # not p02: Ada is not k2's
    assert k2.register_many(phase, label="Dan") == ["p02"]
    robot, k2 = StudyData(tmp_path / "robot"), StudyData(tmp_path / "k2")
    assert robot.id_notes() == ({}, "") and k2.id_notes() == ({}, "")
    k2.delete_participant("p01")  # Bob's line goes, Ada's (robot's p01) stays, and robot's header line
    assert [r[1] for r in rows(key)] == ["name", "Ada Lovelace", "Dan"]
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


def test_init_refuses_a_key_file_another_study_made_its_own_before_anyone_registered(tmp_path, pairplay_cli):
    """trial29 F9: a key file still empty when a second study was made was taken by both (two p01 lines)."""
    key = tmp_path / "private" / "keys.csv"
    StudyData.create(tmp_path / "robot", STUDY, key_file=key)
    assert rows(key)[0][:2] == ["id", "name"]  # a plain CSV header naming its study
    run = pairplay_cli("protocol", "init", tmp_path / "second", "--study", STUDY, "--key-file", key)
    assert run.returncode == 2, run
    assert "Traceback" not in run.stderr and len(run.stderr.strip().splitlines()) == 1, run.stderr
    assert "the key file of study pilot@" in run.stderr and "one study" in run.stderr, run.stderr
    assert not (tmp_path / "second" / "journal.jsonl").exists()
    data = StudyData(tmp_path / "robot")
    assert data.register_many("phase1", label="Ada") == ["p01"] and data.key_file_ids() == ["p01"]
    data.delete_participant("p01")
    assert len(rows(key)) == 1 and rows(key)[0][:2] == ["id", "name"]  # the header stays with the study


@pytest.mark.parametrize("where", ["recordings/k.csv", "keys.csv", "sub/deeper/k.csv"])
def test_init_refuses_a_key_file_inside_another_study_folder(tmp_path, pairplay_cli, where):
    """trial29 F8: only the new study's own folder was refused: a key file (real names) was taken inside another
    study's folder, even its recordings/."""
    StudyData.create(tmp_path / "dry-run", STUDY)
    key = tmp_path / "dry-run" / where
    run = pairplay_cli("protocol", "init", tmp_path / "kf3", "--study", STUDY, "--key-file", key)
    assert run.returncode == 2, run
    assert "Traceback" not in run.stderr and len(run.stderr.strip().splitlines()) == 1, run.stderr
    assert "inside the study folder" in run.stderr and "dry-run" in run.stderr, run.stderr
    assert not key.exists() and not (tmp_path / "kf3" / "journal.jsonl").exists()


def test_registering_a_name_refuses_a_key_file_inside_a_study_folder(tmp_path):
    """Every writer of real names: a settings.json pointing the key file into a study folder (by hand, or a
    folder made a study's since) is refused at registration, nothing written."""
    other = StudyData.create(tmp_path / "other", STUDY)
    data = StudyData.create(tmp_path / "s", STUDY)
    key = other.folder / "policies" / "k.csv"
    key.touch()
    (tmp_path / "s" / "settings.json").write_text(json.dumps({"key_file": str(key)}))
    data = StudyData(tmp_path / "s")
    with pytest.raises(StudyDataError, match="inside the study folder"):
        data.register_many("phase1", label="Ada")
    assert key.read_bytes() == b"" and not data.state.participants
