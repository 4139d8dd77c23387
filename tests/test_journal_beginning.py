"""A journal that lost its beginning (empty, or its StudyCreated line gone) is refused by every verb
(replay/studyjournal.py).

A new user's trial: a 0-byte journal.jsonl in a folder holding a study's data was taken as a new study: status
said nobody was registered, register gave p01 again and rewrote participants.csv down to it. Now every verb,
`protocol repair` too, refuses it in one line saying to put back a backup, and changes no file.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from pairplay.replay.studydata import StudyData, StudyDataError

STUDY = Path(__file__).parent / "data" / "pilot-study.toml"

VERBS = [["protocol", "status"], ["protocol", "register"], ["protocol", "repair"],
         ["protocol", "mark-invalid", "{f}", "pilot-p01-phase1-g1", "--reason", "x"],
         ["participant", "export", "{f}", "p01"], ["participant", "delete", "{f}", "p01", "--yes"], ["report"]]


def files_of(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and p.name != ".pairplay-lock"}


@pytest.fixture(params=["empty", "first line lost"])
def beheaded(request, tmp_path) -> tuple[Path, str]:
    data = StudyData.create(tmp_path / "study", STUDY)
    for _ in range(2):
        data.register("phase1")
    data.write_tables()
    data.close()
    journal = data.folder / "journal.jsonl"
    if request.param == "empty":
        journal.write_bytes(b"")
        what = "it is empty"
    else:
        journal.write_bytes(b"".join(journal.read_bytes().splitlines(keepends=True)[1:]))
        what = "its first line is a ParticipantRegistered, not the StudyCreated line `protocol init` writes"
    return data.given, what


@pytest.mark.parametrize("verb", VERBS, ids=lambda v: " ".join(v[:2]))
def test_every_verb_refuses_a_journal_that_lost_its_beginning(pairplay_cli, beheaded, verb):
    folder, what = beheaded
    before = files_of(folder)
    args = [a.replace("{f}", str(folder)) for a in verb] if "{f}" in verb else [*verb, str(folder)]
    r = pairplay_cli(*args)
    said = "report" if verb[0] == "report" else " ".join(verb[:2])
    journal = folder / "journal.jsonl"
    assert r.returncode == 2 and r.stdout == "", r
    assert r.stderr == (f"pairplay {said}: {journal}: the journal lost its beginning ({what}); read so, the study "
                        "would start again (ids given again, participants.csv rewritten), so every verb refuses it"
                        + (" and `protocol repair` changed nothing" if verb[-1] == "repair" else "")
                        + ": put back a backup of journal.jsonl\n"), r.stderr
    assert files_of(folder) == before  # participants.csv still p01, p02


def test_the_python_api_refuses_it_too(beheaded):
    folder, what = beheaded
    with pytest.raises(StudyDataError, match="lost its beginning"):
        StudyData(folder)
