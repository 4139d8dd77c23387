"""Informed consent in a study with people (trial27 F11).

Before, `grep -ri consent` found nothing: registration recorded an id (and a name in the key file), and nothing
stopped a game for someone whose consent was not recorded. Now registration records consent (ConsentGiven: the
study file's `consent_form` version, the time), participants.csv and the export hold it, a person's game is
refused without it (a persona's is not: no person plays), and a deletion for withdrawn consent says so.
"""

from __future__ import annotations

import csv
import io
import json
import zipfile
from pathlib import Path

import pytest

from pairplay.replay.studydata import StudyData, StudyDataError
from pairplay.schemas.study import StudyFileError, parse_study
from pairplay.services.bus import Bus, BusOptions
from pairplay.services.console.server import ConsoleServer
from pairplay.services.protocol import StudyRunner, scripted_players

from test_console_api import call

STUDY = Path(__file__).parent / "data" / "pilot-study.toml"


def study_with_form(tmp_path: Path, form: str = "v2 2026-11") -> Path:
    text = STUDY.read_text().replace('robot = "none"\n', f'robot = "none"\nconsent_form = "{form}"\n')
    path = tmp_path / "consent-study.toml"
    path.write_text(text)
    return path


def journal(folder: Path) -> list[dict]:
    return [json.loads(line) for line in (folder / "journal.jsonl").read_text().splitlines()]


def table(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_registration_records_consent_in_the_journal_the_table_and_the_export(tmp_path, pairplay_cli):
    folder = tmp_path / "study"
    assert pairplay_cli("protocol", "init", folder, "--study", study_with_form(tmp_path)).returncode == 0
    r = pairplay_cli("protocol", "register", folder, "--consent")
    assert r.returncode == 0 and r.stdout == "p01\n" and r.stderr == "", r
    r = pairplay_cli("protocol", "register", folder)  # a rehearsal's id, or consent still to come: said
    assert r.returncode == 0 and r.stdout == "p02\n" and "no consent recorded" in r.stderr, r
    given = [e for e in journal(folder) if e["event"] == "ConsentGiven"]
    assert [(e["participant"], e["form"]) for e in given] == [("p01", "v2 2026-11")] and given[0]["time_ns"] > 0
    rows = table(folder / "participants.csv")
    assert [(r["participant"], r["consent_form"], bool(r["consent_utc"])) for r in rows] == \
        [("p01", "v2 2026-11", True), ("p02", "", False)]
    status = pairplay_cli("protocol", "status", folder)
    assert "p02: no consent recorded" in status.stdout and "p01: no consent" not in status.stdout, status.stdout
    r = pairplay_cli("protocol", "consent", folder, "p02")
    assert r.returncode == 0 and r.stdout.startswith("p02: consent recorded: form 'v2 2026-11' given "), r
    again = pairplay_cli("protocol", "consent", folder, "p02")
    assert again.returncode == 2 and len(again.stderr.strip().splitlines()) == 1, again
    assert "recorded already" in again.stderr and "Traceback" not in again.stderr
    unknown = pairplay_cli("protocol", "consent", folder, "p09")
    assert unknown.returncode == 2 and "no participant 'p09'" in unknown.stderr, unknown
    assert pairplay_cli("participant", "export", folder, "p01").returncode == 0
    with zipfile.ZipFile(folder / "exports" / "p01.zip") as z:
        [row] = list(csv.DictReader(io.StringIO(z.read("participant.csv").decode())))
        assert row["consent_form"] == "v2 2026-11" and row["consent_utc"] == table(folder / "participants.csv")[0]["consent_utc"]
        assert "Informed consent: form 'v2 2026-11' given " in z.read("README.txt").decode()
        assert b'"ConsentGiven"' in z.read("journal.jsonl")


def test_a_persons_game_is_refused_without_consent_a_personas_is_not(tmp_path):
    data = StudyData.create(tmp_path / "study", study_with_form(tmp_path))
    data.register_many("phase1", count=2)
    with Bus(BusOptions()) as bus:
        runner = StudyRunner(data, bus)
        with pytest.raises(StudyDataError, match="p01 has no consent recorded"):
            runner.run_game("p01", "phase1", 0)  # a person, on the board
        assert not data.state.games and "GameStarted" not in (data.folder / "journal.jsonl").read_text()
        # a persona plays (a rehearsal: pilot, serve --pilot): no person, nothing to consent to
        played = runner.run_game("p01", "phase1", 0, scripted_players(runner, {"p01": "tatiana"})("p01", "phase1", 0))
        assert played.ended.outcome == "completed" and played.scripted == "tatiana"
        data.record_consent("p02")
        runner.check_step("p02", "phase1", 0)
        data.check_consent("p02")  # the person may play now


def test_the_console_refuses_the_next_step_of_a_person_without_consent_and_records_it(tmp_path):
    data = StudyData.create(tmp_path / "study", study_with_form(tmp_path))
    with Bus(BusOptions()) as bus:
        server = ConsoleServer(StudyRunner(data, bus)).start()
        try:
            url = f"{server.url}/api/console/%s?token={server.token}"
            status, body = call(url % "register", {"phase": "phase1"})
            assert status == 200 and body == {"registered": ["p01"], "consent": False}, body
            status, body = call(url % "next", {})
            assert status == 400 and "p01 has no consent recorded" in body["error"], body
            assert not data.state.games
            _, state = call(url % "state")
            assert state["participants"][0]["consent"] == "" and state["consent_form"] == "v2 2026-11"
            status, body = call(url % "consent", {"participant": "p01"})
            assert status == 200 and body["consent"] == "p01" and body["form"] == "v2 2026-11", body
            assert body["given"].startswith("form 'v2 2026-11' given ") and "recorded" not in body["given"], body
            status, body = call(url % "register", {"phase": "phase1", "consent": True})
            assert status == 200 and body["registered"] == ["p02"] and body["consent"] is True
            _, state = call(url % "state")
            assert all(p["consent"].startswith("form 'v2 2026-11' given ") for p in state["participants"]), state
        finally:
            server.close()


def test_a_deletion_for_withdrawn_consent_says_so_without_the_id(tmp_path, pairplay_cli):
    data = StudyData.create(tmp_path / "study", study_with_form(tmp_path))
    data.register_many("phase1", count=2, consent=True)
    r = pairplay_cli("participant", "delete", data.folder, "p02", "--yes", "--consent-withdrawn")
    assert r.returncode == 0 and "consent withdrawn" in r.stdout, r
    lines = journal(data.folder)
    deleted = [e for e in lines if e["event"] == "ParticipantDeleted"]
    assert len(deleted) == 1 and deleted[0]["consent_withdrawn"] is True
    assert "p02" not in (data.folder / "journal.jsonl").read_text()  # their ConsentGiven went with them
    assert [e["participant"] for e in lines if e["event"] == "ConsentGiven"] == ["p01"]
    r = pairplay_cli("participant", "delete", data.folder, "p01", "--yes")  # an erasure request: not withdrawal
    assert r.returncode == 0 and "consent withdrawn" not in r.stdout
    assert [e["consent_withdrawn"] for e in journal(data.folder) if e["event"] == "ParticipantDeleted"] == [True, False]


def test_a_study_folder_from_before_consent_loads_and_waits_for_it(tmp_path, pairplay_cli):
    """An older folder: its study file has no consent_form, its journal no ConsentGiven, its participants.csv
    no consent columns. It loads and reads as it was; a person's next game waits for `protocol consent`."""
    data = StudyData.create(tmp_path / "study", STUDY)
    data.register_many("phase1", count=2)
    (data.folder / "participants.csv").write_text("participant,joins,registered_utc,scripted\n"
                                                  "p01,phase1,2026-11-01T10:00:00Z,\np02,phase1,2026-11-01T10:00:00Z,\n")
    old = StudyData(data.folder)
    assert list(old.state.participants) == ["p01", "p02"] and old.state.consent == {}
    status = pairplay_cli("protocol", "status", data.folder)
    assert status.returncode == 0 and "p01: no consent recorded" in status.stdout, status
    with pytest.raises(StudyDataError, match="no consent recorded"):
        old.check_consent("p01")
    r = pairplay_cli("protocol", "consent", data.folder, "p01")
    assert r.returncode == 0 and "the study's form (its version not named)" in r.stdout, r
    StudyData(data.folder).check_consent("p01")
    assert table(data.folder / "participants.csv")[0]["consent_utc"]


@pytest.mark.parametrize("form", ["v2\n2026", " v2", "x" * 101])
def test_a_consent_form_version_is_one_short_line(form):
    text = STUDY.read_text().replace('robot = "none"\n', f'robot = "none"\nconsent_form = {json.dumps(form)}\n')
    with pytest.raises(StudyFileError, match="consent_form.*one line of at most 100"):
        parse_study(text, "s.toml")


def test_the_example_names_a_consent_form(pairplay_cli):
    r = pairplay_cli("protocol", "check", "thesis-ch7")
    assert r.returncode == 0 and "  consent form: 'thesis-ch7 consent form v1'" in r.stdout, r
