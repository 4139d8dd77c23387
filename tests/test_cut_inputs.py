"""A file cut short (a copy or a save that did not finish, a crash mid-append) is said with where and what to do.

A new user's trial: a half-written last line of a study's `journal.jsonl` (`truncate -s -5`) blocked every
study verb with msgspec's "Input data was truncated" and no advice; a cut policy file said the same words.
Now every JSON, JSONL or TOML input names the file, the place (line, byte) and what to do; a journal's torn
LAST line is said to be a crash's, and `pairplay protocol repair STUDY` sets it aside beside the journal
(never deleting a byte) so the study goes on; a damaged line elsewhere is not a crash's: repair refuses it
and changes nothing (replay/studyjournal.py).
"""

from __future__ import annotations

from pathlib import Path

import msgspec
import pytest

from pairplay.replay.studydata import StudyData
from pairplay.schemas import policy as policy_file
from pairplay.schemas.robot import RobotConfig
from pairplay.schemas.study import example_text

from test_input_files import EMPTY_INPUTS, SAMPLE, _verb_id

STUDY = Path(__file__).parent / "data" / "pilot-study.toml"
REPAIR = "`pairplay protocol repair {folder}` sets it aside in a file beside the journal and keeps every whole line"


def a_study(tmp_path: Path, registered: int = 3) -> Path:
    data = StudyData.create(tmp_path / "study", STUDY)
    for _ in range(registered):
        data.register("phase1")
    data.close()
    return data.given


def files_of(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and p.name != ".pairplay-lock"}


STUDY_VERBS = [["protocol", "status"], ["protocol", "register"], ["protocol", "pilot", "{f}", "--personas", "blind"],
               ["protocol", "serve"], ["protocol", "mark-invalid", "{f}", "pilot-p01-phase1-g1", "--reason", "x"],
               ["participant", "export", "{f}", "p01"], ["participant", "delete", "{f}", "p01", "--yes"], ["report"]]


@pytest.mark.parametrize("verb", STUDY_VERBS, ids=lambda v: " ".join(v[:2]))
def test_a_torn_last_journal_line_is_a_crash_and_every_verb_names_the_repair(pairplay_cli, tmp_path, verb):
    folder = a_study(tmp_path)
    journal = folder / "journal.jsonl"
    journal.write_bytes(journal.read_bytes()[:-5])  # the crash mid-append: `truncate -s -5`
    torn = len(journal.read_bytes().splitlines()[-1])
    before = files_of(folder)
    args = [a.replace("{f}", str(folder)) for a in verb] if "{f}" in verb else [*verb, str(folder)]
    r = pairplay_cli(*args)
    assert r.returncode == 2 and r.stdout == "", r
    assert r.stderr == (f"pairplay {' '.join(verb[:2]) if verb[0] != 'report' else 'report'}: {journal}:4: its last "
                        f"line is cut short ({torn} bytes, no end of line): pairplay stopped while it wrote it (a crash, "
                        f"a power cut, a full disk); {REPAIR.format(folder=folder)}\n"), r.stderr
    assert files_of(folder) == before


def test_repair_sets_the_torn_line_aside_unchanged_and_the_study_goes_on(pairplay_cli, tmp_path):
    folder = a_study(tmp_path)
    journal = folder / "journal.jsonl"
    whole = journal.read_bytes()
    head = whole[:whole.rstrip(b"\n").rfind(b"\n") + 1]  # the first three lines: StudyCreated, p01, p02
    journal.write_bytes(whole[:-5])
    r = pairplay_cli("protocol", "repair", folder)
    assert r.returncode == 0 and r.stderr == "", r
    [aside] = folder.glob("journal.jsonl.torn-*")
    assert aside.read_bytes() == whole[len(head):-5], "the torn bytes, as they were"
    assert journal.read_bytes() == head
    assert r.stdout.startswith(f"set aside the cut last line of {journal} ({len(whole) - len(head) - 5} bytes, what a crash left of the "
                               f"event it wrote) in {folder / aside.name}; the journal keeps its 3 whole lines"), r
    # the study goes on from its whole lines: p03's registration was the torn line, and its id is never given
    # again (tests/test_ids_never_twice.py), so p04 is given now
    assert r.stdout.splitlines()[-1].startswith("the cut line was the registration of p03: that id will not be given")
    assert pairplay_cli("protocol", "register", folder).stdout == "p04\n"
    # a second crash's torn line goes to a file of its own, never over the first
    journal.write_bytes(journal.read_bytes()[:-7])
    assert pairplay_cli("protocol", "repair", folder).returncode == 0
    assert len(list(folder.glob("journal.jsonl.torn-*"))) == 2 and aside.read_bytes() == whole[len(head):-5]
    r = pairplay_cli("protocol", "repair", folder)
    assert r.returncode == 0 and r.stdout == f"{journal}: nothing to repair: every line is whole (3 lines)\n", r
    assert pairplay_cli("protocol", "register", folder).stdout == "p05\n"
    # a torn line naming a participant of the journal: their deletion erases it with the rest of their lines
    with open(journal, "ab") as f:
        f.write(b'{"event":"SessionMarkedInvalid","time_ns":1,"by":"experimenter","participant":"p05","ses')
    assert pairplay_cli("protocol", "repair", folder).returncode == 0
    r = pairplay_cli("participant", "delete", folder, "p05", "--yes")
    assert r.returncode == 0 and len(list(folder.glob("journal.jsonl.torn-*"))) == 2, r
    assert all(b'"p05"' not in t.read_bytes() for t in folder.glob("journal.jsonl.torn-*"))


def test_a_damaged_line_that_is_not_the_last_is_refused_and_repair_changes_nothing(pairplay_cli, tmp_path):
    folder = a_study(tmp_path)
    journal = folder / "journal.jsonl"
    lines = journal.read_bytes().splitlines(keepends=True)
    lines[1] = lines[1][:30] + b"\n"  # a hand edit, a damaged disk: not what a crash mid-append leaves
    journal.write_bytes(b"".join(lines))
    before = files_of(folder)
    r = pairplay_cli("protocol", "status", folder)
    assert r.returncode == 2 and r.stderr == (
        f"pairplay protocol status: {journal}:2: cut short: it ends inside its JSON at line 1 (byte 30, its end): "
        "a copy or a save that did not finish? put back a whole copy; not a crash's cut last line: put back a "
        "backup of journal.jsonl, or correct line 2 by hand (one JSON object a line, docs/study.md)\n"), r.stderr
    r = pairplay_cli("protocol", "repair", folder)
    assert r.returncode == 2 and "not a crash's cut last line, so `protocol repair` changed nothing" in r.stderr, r
    assert len(r.stderr.splitlines()) == 1 and files_of(folder) == before


def test_a_last_line_whole_but_for_its_end_of_line_is_read_and_the_next_line_starts_its_own(pairplay_cli, tmp_path):
    folder = a_study(tmp_path)
    journal = folder / "journal.jsonl"
    journal.write_bytes(journal.read_bytes()[:-1])
    r = pairplay_cli("protocol", "register", folder)
    assert r.returncode == 0 and r.stdout == "p04\n", r  # (it was glued onto p03's line: the journal then unread)
    assert pairplay_cli("protocol", "status", folder).returncode == 0
    assert len(journal.read_bytes().splitlines()) == 5


def _cut(data: bytes) -> bytes:
    return data[:len(data) // 2]


def _whole_input(verb: list[str]) -> bytes:
    """A whole file of the kind `verb` reads (EMPTY_INPUTS)."""
    from pairplay.replay.rebuild import rebuild_recording

    if verb[0] in ("session", "combine"):
        return policy_file.FILE.encode(rebuild_recording(SAMPLE).policy)
    if verb[0] == "protocol":
        return example_text().encode()
    if verb[0] == "sweep":
        return b'seeds = 2\n[study]\npersonas = "blind"\n[grid]\nreward_bonus = ["correct", "consistent"]\n'
    if "--robot-config" in verb:
        return msgspec.json.format(msgspec.json.encode(RobotConfig()), indent=1)
    if "--calibration" in verb:
        from importlib import resources
        return resources.files("pairplay.services.robot").joinpath("calibration_default.json").read_bytes()
    return b'{\n  mode: "peer",\n  listen: {endpoints: ["tcp/127.0.0.1:0"]},\n}\n'  # a Zenoh JSON5 config


@pytest.mark.parametrize("verb", [v for v in EMPTY_INPUTS if v[0] != "rebuild"], ids=_verb_id)
def test_every_json_or_toml_input_cut_short_says_where_and_what_to_do(tmp_path, capsys, verb):
    from pairplay.cli.main import main

    args = [a.format(f=tmp_path / "in", tmp=tmp_path) for a in verb]
    given = next(a for a in args if a.startswith(str(tmp_path / "in")))
    Path(given).write_bytes(_cut(_whole_input(verb)))
    assert main(args) == 2
    out, err = capsys.readouterr()
    [line] = err.splitlines()
    assert given in line and "line " in line and "cut short" in line and "put back a whole copy" in line, line
    assert "Input data was truncated" not in line
    assert sorted(p.name for p in tmp_path.iterdir()) == [Path(given).name]


def test_a_study_folders_cut_settings_say_where_and_what_to_do(pairplay_cli, tmp_path):
    folder = a_study(tmp_path)
    (folder / "settings.json").write_bytes(b'{"key_file": "')
    r = pairplay_cli("protocol", "status", folder)
    assert r.returncode == 2 and r.stderr == (
        "pairplay protocol status: not the study's settings: cut short: it ends inside its JSON at line 1 (byte 14, "
        'its end): a copy or a save that did not finish? put back a whole copy; it is {"key_file": "<path or '
        f'empty>"}} ({folder / "settings.json"})\n'), r.stderr


@pytest.mark.parametrize("cut_after", ['robot = "virtual"', "# Phase 1 (7.2): half of the users"])
def test_a_study_file_cut_between_tables_says_where_it_ends(pairplay_cli, tmp_path, cut_after):
    """A study file cut before its [[phase]] tables is valid TOML up to the cut: it said only "needs a [phase]
    table", not that the file was cut (it ends without a newline: a whole file's last line has one)."""
    from pairplay.schemas.study import example_text
    text = example_text()
    cut = text[:text.index(cut_after) + len(cut_after)]
    (tmp_path / "cut.toml").write_text(cut)
    r = pairplay_cli("protocol", "check", tmp_path / "cut.toml")
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1, r
    assert "needs a [phase] table; the file ends at line " in lines[0] and "cut short there?" in lines[0], lines
    assert f"line {cut.count(chr(10)) + 1} " in lines[0], lines
    (tmp_path / "whole.toml").write_text(cut + "\n")  # ends as a whole file does: no word of a cut
    r = pairplay_cli("protocol", "check", tmp_path / "whole.toml")
    assert r.returncode == 2 and r.stderr.rstrip().endswith("needs a [phase] table"), r
