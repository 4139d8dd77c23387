"""A participant's deletion keeps no free text of theirs; every free text the study takes is one line.

A new user's trial (trial33 C): `participant delete --consent-withdrawn` kept the mark's reason of the deleted
person's game in the flaw it keeps (ParticipantDeleted `flaws_kept`): "deleted (Anna Schmidt) told us she has
epilepsy" stayed in the journal, status, sessions.csv, the console and the report, only the id replaced. Now the
flaw is kept (which bias policy, that a game it took was marked invalid, when) and its reason withheld
(replay/biases.py WITHHELD), in what the deletion writes and in how an older pairplay's kept flaw is read; their
name from the key file goes from other people's reasons as their id does. trial33 I: a mark's reason with a NUL
or an ESC went raw into sessions.csv and report.md: refused at entry (studydata.refuse_control), escaped where an
older journal holds one. Real CLI runs of a study of 2-round games (tests/data/pilot-study.toml), personas playing.
"""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import pytest

from pairplay.replay.studydata import StudyData, StudyDataError
from pairplay.services.bus import Bus, BusOptions
from pairplay.services.console.app import Console
from pairplay.services.protocol import StudyRunner, check_answers

STUDY = Path(__file__).parent / "data" / "pilot-study.toml"
P01_G2, P02_G1 = "pilot-p01-phase1-g2", "pilot-p02-phase1-g1"  # p01's game the bias policy took; p02's game
V1 = "merged/phase2-bias.policy.json"
WITHHELD = "reason withheld: its participant was deleted"  # replay/biases.py WITHHELD, as every reader says it
SECRET = "p01 (Anna Schmidt) told us she has epilepsy, stopped"
# another's mark naming them as an experimenter writes (trial34 D: only the whole "Anna Schmidt" went; a first name,
# a surname, joined forms and an e-mail said who p01 was), and what the deletion leaves of it
NAMED = ("anna schmidt's mother came in; Anna's bag; the SCHMIDTS; A. Schmidt; Anna-Schmidt; annaschmidt@uni.de; "
         "Schmidt_Anna; a banana")
UNNAMED = "deleted's mother came in; deleted's bag; the deleted; A. deleted; deleted; deleted@uni.de; deleted_deleted; a banana"


@pytest.fixture(scope="module")
def pairplay_cli():
    from cli_zygote import shared

    zygote = shared()
    return lambda *args, cwd: zygote.run([str(a) for a in args], Path(cwd), timeout=300)


@pytest.fixture(scope="module")
def played(tmp_path_factory, pairplay_cli):
    """A study of 2 people named in its key file, played to its end by `protocol pilot`."""
    root = tmp_path_factory.mktemp("withholds")
    key = root / "private" / "keys.csv"
    for args in (["init", "s", "--study", STUDY, "--key-file", key], ["register", "s", "--name", "Anna Schmidt"],
                 ["register", "s", "--name", "Bob Jones"], ["pilot", "s", "--personas", "blind,deaf"]):
        ran = pairplay_cli("protocol", *args, cwd=root)
        assert ran.returncode == 0, ran.stderr
    assert "plan complete" in ran.stdout
    return root


def copy(played: Path, tmp_path: Path) -> Path:
    """A copy of the played study, its settings naming the copy of its key file (they name it absolute)."""
    shutil.copytree(played, tmp_path, dirs_exist_ok=True)
    (tmp_path / "s" / "settings.json").write_text(json.dumps({"key_file": str(tmp_path / "private" / "keys.csv")}))
    return tmp_path / "s"


def text_of(folder: Path) -> str:
    """Every file of the study folder, and the key file, as one text."""
    files = [f for f in folder.rglob("*") if f.is_file()] + [folder.parent / "private" / "keys.csv"]
    return "\n".join(f.read_bytes().decode("utf-8", "replace") for f in files)


def sessions_csv(folder: Path) -> dict[str, dict[str, str]]:
    with open(folder / "sessions.csv", newline="") as f:
        return {r["session"]: r for r in csv.DictReader(f)}


@pytest.mark.parametrize("withdrawn", [["--consent-withdrawn"], []])
def test_a_deletion_keeps_the_flaw_and_withholds_the_marks_reason(played, tmp_path, pairplay_cli, withdrawn):
    """"(Anna Schmidt) told us she has epilepsy" outlived the erasure in the journal, status, sessions.csv, the
    console and the report (a new user's trial, trial33 C)."""
    folder = copy(played, tmp_path)
    ran = pairplay_cli("protocol", "mark-invalid", "s", P01_G2, "--reason", SECRET, cwd=tmp_path)
    assert ran.returncode == 0, ran.stderr
    # another person's mark that names them: their name goes as their id does
    ran = pairplay_cli("protocol", "mark-invalid", "s", P02_G1, "--reason", NAMED, cwd=tmp_path)
    assert ran.returncode == 0, ran.stderr
    if withdrawn:  # a consent is withdrawn only once it is recorded (the pilot's personas played without one)
        ran = pairplay_cli("protocol", "consent", "s", "p01", cwd=tmp_path)
        assert ran.returncode == 0, ran.stderr
    ran = pairplay_cli("participant", "delete", "s", "p01", "--yes", *withdrawn, cwd=tmp_path)
    assert ran.returncode == 0, ran.stderr
    assert f"merged policy made with their game marked invalid since: {V1} (kept flagged without their id, " \
           f"{WITHHELD};" in ran.stdout and "Anna" not in ran.stdout and "epilepsy" not in ran.stdout
    assert "their name (from the key file, whole or a part of it) replaced by `deleted` in 1 kept reason of other " \
           "people's games" in ran.stdout
    assert pairplay_cli("report", "s", cwd=tmp_path).returncode == 0
    kept = f"a game of a deleted participant (marked invalid since: {WITHHELD})"  # beside p02's game's mark
    status = pairplay_cli("protocol", "status", "s", cwd=tmp_path).stdout
    state = json.dumps(Console(StudyRunner(StudyData(folder), None), "token").state())
    for said in (text_of(folder), status, state):
        assert "epilepsy" not in said and "anna" not in said.lower() and "schmidt" not in said.lower() \
            and "p01" not in said
    assert kept in status and kept in state and kept in (folder / "report" / "report.md").read_text()
    assert kept in sessions_csv(folder)["pilot-p02-phase2-g1"]["bias_flawed"]
    assert sessions_csv(folder)[P02_G1]["invalid"] == UNNAMED  # p02's own words stay


def test_a_kept_flaw_an_older_pairplay_wrote_with_its_reason_is_read_withheld_and_dropped_at_the_next_deletion(
        played, tmp_path, pairplay_cli):
    """A journal whose deletion kept the reason (pairplay before this fix): no reader shows it, and the next
    deletion rewrites the journal without it."""
    folder = copy(played, tmp_path)
    assert pairplay_cli("protocol", "mark-invalid", "s", P01_G2, "--reason", "x", cwd=tmp_path).returncode == 0
    assert pairplay_cli("participant", "delete", "s", "p01", "--yes", cwd=tmp_path).returncode == 0
    journal = folder / "journal.jsonl"
    lines = [json.loads(line) for line in journal.read_text().splitlines()]
    for line in lines:  # the reason as a deletion before this fix kept it, the id redacted
        for flaw in line.get("flaws_kept", []):
            flaw["reason"] = "deleted told us she has epilepsy"
    assert "epilepsy" in str(lines)
    journal.write_text("".join(json.dumps(line) + "\n" for line in lines))
    assert "epilepsy" not in pairplay_cli("protocol", "status", "s", cwd=tmp_path).stdout
    assert pairplay_cli("report", "s", cwd=tmp_path).returncode == 0
    assert "epilepsy" not in (folder / "report" / "report.md").read_text()
    assert "epilepsy" not in (folder / "sessions.csv").read_text()
    assert pairplay_cli("participant", "delete", "s", "p02", "--yes", cwd=tmp_path).returncode == 0
    assert "epilepsy" not in text_of(folder)


@pytest.mark.parametrize("reason, shown", [("left\x1b[31m early", r"'\x1b' at 4"), ("a\nb", r"'\n' at 1"),
                                           ("nul\x00", r"'\x00' at 3")])
def test_a_mark_reason_with_a_control_character_is_refused_in_one_line(played, tmp_path, pairplay_cli, reason,
                                                                      shown):
    """An ESC (the CLI) or a NUL (the console) went raw into sessions.csv and report.md (trial33 I)."""
    folder = copy(played, tmp_path)
    journal = (folder / "journal.jsonl").read_bytes()
    ran = pairplay_cli("protocol", "mark-invalid", "s", P02_G1, "--reason", reason, cwd=tmp_path)
    assert ran.returncode == 2 and ran.stdout == ""
    assert ran.stderr == (f"pairplay protocol mark-invalid: the reason holds a control character ({shown}): give it "
                          "as one line of text, without tabs\n")
    assert (folder / "journal.jsonl").read_bytes() == journal


def test_the_console_refuses_a_control_character_in_every_reason(played, tmp_path):
    """The console's mark, pause and abort: 400 with one line, nothing journaled."""
    from test_console_api import call
    from pairplay.services.console.server import ConsoleServer

    folder = copy(played, tmp_path)
    journal = (folder / "journal.jsonl").read_bytes()
    with Bus(BusOptions()) as bus:
        server = ConsoleServer(StudyRunner(StudyData(folder), bus)).start()
        try:
            answers = [call(f"{server.url}/api/console/control/{action}?token={server.token}", body)
                       for action, body in (("invalid", {"session": P02_G1, "reason": "nul\x00"}),
                                            ("pause", {"reason": "esc\x1b"}), ("abort", {"reason": "x\x00"}))]
        finally:
            server.close()
    for status, answer in answers:
        assert status == 400 and "holds a control character" in answer["error"], answer
    assert (folder / "journal.jsonl").read_bytes() == journal


def test_a_reason_an_older_pairplay_journaled_raw_is_written_escaped(played, tmp_path, pairplay_cli):
    """A journal holding a mark's ESC and NUL (taken before this fix): sessions.csv, status and the report show
    them escaped, never raw."""
    folder = copy(played, tmp_path)
    assert pairplay_cli("protocol", "mark-invalid", "s", P02_G1, "--reason", "RAW", cwd=tmp_path).returncode == 0
    journal = folder / "journal.jsonl"
    journal.write_text(journal.read_text().replace("RAW", "left\\u001b[31m early\\u0000"))
    # the next write of the tables (another mark) writes them from the journal
    assert pairplay_cli("protocol", "mark-invalid", "s", P01_G2, "--reason", "x", cwd=tmp_path).returncode == 0
    status = pairplay_cli("protocol", "status", "s", cwd=tmp_path)
    assert pairplay_cli("report", "s", cwd=tmp_path).returncode == 0
    for said in (status.stdout, (folder / "sessions.csv").read_text(), (folder / "report" / "report.md").read_text()):
        assert "\x1b" not in said and "\x00" not in said
    assert sessions_csv(folder)[P02_G1]["invalid"] == r"left\x1b[31m early\x00"


def test_a_questionnaire_answer_holds_lines_but_no_other_control_character():
    """A person's free text may run over lines; a NUL or an ESC would land raw in answers.csv."""
    from pairplay.schemas.study import parse_study  # the items of a real study file

    items = parse_study(STUDY.read_text()).questions("after-game", returning=False)
    item = next(i for i in items if i.id == "comments")  # its free text
    assert check_answers([item], {item.id: "one\nand two\tthree"}) == {item.id: "one\nand two\tthree"}
    for bad in ("nul\x00", "esc\x1b[2J"):
        with pytest.raises(StudyDataError, match="holds a control character"):
            check_answers([item], {item.id: bad})


def test_the_console_shows_nothing_of_a_deleted_person_it_held_beside_the_journal(played, tmp_path):
    """The console's deletion rewrote the journal, and the page went on showing their last game's panel and the
    outcome line of their step (an abort's reason in it) until the console was restarted."""
    from test_console_api import call
    from pairplay.services.console.server import ConsoleServer
    from pairplay.services.protocol import Live

    folder = copy(played, tmp_path)
    with Bus(BusOptions()) as bus:
        runner = StudyRunner(StudyData(folder), bus)
        server = ConsoleServer(runner).start()
        try:  # what the console held after the step of p01's game an abort ended (the state its run leaves)
            runner.live = Live(session=P01_G2, participant="p01", phase="phase1", game=1, state="ended")
            server.console.last = {"step": "p01: phase1 game 2", "ok": True,
                                   "message": f"{P01_G2}: aborted (aborted: Anna felt unwell), 1 round"}
            status, answer = call(f"{server.url}/api/console/delete?token={server.token}",
                                  {"participant": "p01", "confirm": "p01"})
            assert status == 200, answer
            _, state = call(f"{server.url}/api/console/state?token={server.token}")
        finally:
            server.close()
    shown = json.dumps(state)
    assert "p01" not in shown and "Anna" not in shown and "unwell" not in shown


def test_a_file_of_the_users_in_report_that_names_them_by_name_is_said_to_name_them(played, tmp_path, pairplay_cli):
    """Their deletion said a notes.md holding their name but not their id "check it does not mention p01", when
    the key file it had just read said whose name it was."""
    folder = copy(played, tmp_path)
    assert pairplay_cli("report", "s", cwd=tmp_path).returncode == 0
    (folder / "report" / "notes.md").write_text("Schmidt was tired\n")  # a part of the name (trial34 D)
    ran = pairplay_cli("participant", "delete", "s", "p01", "--yes", cwd=tmp_path)
    assert ran.returncode == 0, ran.stderr
    line, = [x for x in ran.stderr.splitlines() if "notes.md" in x]
    assert "it names p01 (their id, or their name or a part of it, from the key file): edit it by hand" in line


@pytest.mark.parametrize("name, said, left", [
    ("Jürgen Müller", "jürgen's dad; MÜLLER; Mueller; Juergen; Jurgen; Muller; a mule",
     "deleted's dad; deleted; deleted; deleted; deleted; deleted; a mule"),
    ("Zoë O'Brien", "O'Brien's kid; O\u2019Brien; OBrien; Brien; Zoe; zoë; ZOË; a zoo",
     "deleted's kid; deleted; deleted; deleted; deleted; deleted; deleted; a zoo"),
    # trial36 D3: letters NFKD keeps whole, Nordic spellings, their mixes, and the joined forms of every spelling
    ("Łukasz Søndergård", "Lukasz's dad; Sondergard; Soendergaard; Sondergaard; lukasz.sondergard@uni.dk; a sonde",
     "deleted's dad; deleted; deleted; deleted; deleted@uni.dk; a sonde"),
    ("Jürgen Müller", "juergenmueller@uni.de; jurgenmuller; Jürgens", "deleted@uni.de; deleted; deleted"),
    # trial36 D4: a name in a script written without spaces, inside a sentence; one of one-character parts
    ("王伟", "王伟的妈妈来了; 伟大", "deleted的妈妈来了; 伟大"),
    ("李 娜", "李娜来了; a banana", "deleted来了; a banana"),
    ("山田 太郎", "山田太郎さん; 太郎くん", "deletedさん; deletedくん")])
def test_a_name_goes_from_kept_reasons_in_the_spellings_a_keyboard_gives_it(name, said, left):
    """trial35 D1: "Mueller", "Juergen", "Jurgen", "Zoe", "OBrien" stayed in another person's kept reason after
    the deletion of Jürgen Müller and Zoë O'Brien: only the spellings of the key file went."""
    import re

    from pairplay.replay.studydata import _name_pattern
    assert re.sub(_name_pattern(name), "deleted", said, flags=re.IGNORECASE) == left


def test_a_deletion_of_someone_the_key_file_has_no_line_of_says_their_name_was_not_checked(played, tmp_path,
                                                                                          pairplay_cli):
    """trial35 D2: their key-file line gone by a hand edit, the deletion scrubbed no name from the kept reasons and
    said nothing of it."""
    folder = copy(played, tmp_path)
    keys = tmp_path / "private" / "keys.csv"
    keys.write_text("".join(line for line in keys.read_text().splitlines(True) if not line.startswith("p01,")))
    ran = pairplay_cli("protocol", "mark-invalid", "s", P02_G1, "--reason", "Anna's mother came in", cwd=tmp_path)
    assert ran.returncode == 0, ran.stderr
    ran = pairplay_cli("participant", "delete", "s", "p01", "--yes", cwd=tmp_path)
    assert ran.returncode == 0, ran.stderr
    assert f"p01 had no line in the key file {keys}: their name is not known here, so the kept reasons of other " \
           "people's games were not checked for it" in ran.stderr, ran.stderr
    assert folder.is_dir()


def test_a_folder_where_the_key_file_should_be_is_said_as_a_folder(played, tmp_path, pairplay_cli):
    """trial36 K1: the refusal was right, its words ("is not there (an unmounted drive?)") wrong."""
    folder = copy(played, tmp_path)
    keys = tmp_path / "private" / "keys.csv"
    keys.unlink()
    keys.mkdir()
    ran = pairplay_cli("participant", "delete", "s", "p01", "--yes", cwd=tmp_path)
    assert ran.returncode == 2 and len(ran.stderr.strip().splitlines()) == 1, ran.stderr
    assert f"p01: the key file {keys} is a folder, not the key file: their name would stay in it; put the key file " \
           "back there first, then delete" in ran.stderr, ran.stderr
    assert (folder / "recordings").is_dir() and any((folder / "recordings").iterdir())  # nothing deleted
