"""A participant id is never given twice, whatever a crash or a damaged journal left (replay/studydata.py
`ids_on_record`).

A new user's trial: `register` writes the key-file line before the journal line, so a crash between them, or a
torn registration set aside by `protocol repair`, left an id only the key file (or the torn file) showed, and the
next `register` gave it again: the key file held p02 for Alice's... and Carol's, and a deletion of p02 erased both.
Now an id any record shows (the key file, participants.csv, a torn line set aside) is not given again; repair
says the torn line's id; status lists a key-file id the journal never got; a deletion of it, or of an id the key
file holds twice, is refused in one line and changes nothing.
"""

from __future__ import annotations

import csv
from pathlib import Path

import pytest


def key_ids(key: Path) -> list[str]:
    with open(key, newline="") as f:
        return [r[0] for r in csv.reader(f) if r][1:]  # after the header `protocol init` writes


def a_study(cli, tmp_path: Path) -> tuple[Path, Path]:
    folder, key = tmp_path / "k1", tmp_path / "keys" / "k.csv"
    r = cli("protocol", "init", folder, "--study", "thesis-ch7", "--key-file", key)
    assert r.returncode == 0, r
    return folder, key


def register(cli, folder: Path, name: str) -> str:
    r = cli("protocol", "register", folder, "--name", name)
    assert r.returncode == 0 and r.stderr.startswith("pairplay protocol register: no consent recorded"), r
    return r.stdout.strip()


def test_a_torn_registration_set_aside_by_repair_is_never_given_again(pairplay_cli, tmp_path):
    folder, key = a_study(pairplay_cli, tmp_path)
    assert [register(pairplay_cli, folder, n) for n in ("Alice", "Bob")] == ["p01", "p02"]
    journal = folder / "journal.jsonl"
    journal.write_bytes(journal.read_bytes()[:-7])  # `truncate -s -7`: Bob's journal line torn, his key line kept
    r = pairplay_cli("protocol", "repair", folder)
    assert r.returncode == 0 and r.stdout.splitlines()[-1] == (
        "the cut line was the registration of p02: that id will not be given again; its key-file line, if any, "
        "stays (`protocol status` lists it)"), r
    assert register(pairplay_cli, folder, "Carol") == "p03"  # was p02: Bob's id, given again
    assert key_ids(key) == ["p01", "p02", "p03"]
    r = pairplay_cli("protocol", "status", folder)
    assert r.returncode == 0 and ("p02: in the key file only: not registered (a crash cut its registration, or a "
                                  "hand edit): no data here; the id is not given again") in r.stdout.splitlines(), r
    # his id has no data here: a deletion of it is one line, and erases nobody (Carol's line stays)
    before = key.read_bytes()
    r = pairplay_cli("participant", "delete", folder, "p02", "--yes")
    assert r.returncode == 2 and r.stdout == "" and len(r.stderr.splitlines()) == 1, r
    assert "p02 is in the key file but was never journaled" in r.stderr and str(key) in r.stderr, r
    assert key.read_bytes() == before


def test_a_crash_between_the_key_line_and_the_journal_line_leaves_an_id_never_given_again(pairplay_cli, tmp_path):
    folder, key = a_study(pairplay_cli, tmp_path)
    journal = folder / "journal.jsonl"
    whole = journal.read_bytes()
    assert register(pairplay_cli, folder, "Alice") == "p01"
    journal.write_bytes(whole)  # the crash before the journal line: the key file holds p01, the journal nobody
    (folder / "participants.csv").unlink()  # (nor its table: written after)
    assert register(pairplay_cli, folder, "Bob") == "p02"  # was p01 again
    # a deletion keeps no id: p01 left by the crash, p02 deleted, the next is p03, not p02 again
    assert pairplay_cli("participant", "delete", folder, "p02", "--yes").returncode == 0
    assert register(pairplay_cli, folder, "Carol") == "p03"
    assert key_ids(key) == ["p01", "p03"]


def test_participants_csv_is_a_record_of_ids_given(pairplay_cli, tmp_path):
    folder, key = a_study(pairplay_cli, tmp_path)
    journal = folder / "journal.jsonl"
    whole = journal.read_bytes()
    r = pairplay_cli("protocol", "register", folder, "--count", "2")
    assert r.stdout.split() == ["p01", "p02"], r
    journal.write_bytes(whole + journal.read_bytes()[len(whole):].splitlines(keepends=True)[0])  # p02's line lost
    assert register(pairplay_cli, folder, "Dan") == "p03"


def test_an_id_the_key_file_holds_twice_is_never_deleted_as_one_person(pairplay_cli, tmp_path):
    """A key file an older pairplay wrote p01 twice in: the deletion would erase both people's names."""
    folder, key = a_study(pairplay_cli, tmp_path)
    assert register(pairplay_cli, folder, "Alice") == "p01"
    with open(key, "a", newline="") as f:
        csv.writer(f).writerow(["p01", "Bob"])
    before = {p: p.read_bytes() for p in [key, folder / "journal.jsonl"]}
    r = pairplay_cli("participant", "delete", folder, "p01", "--yes")
    assert r.returncode == 2 and r.stdout == "" and len(r.stderr.splitlines()) == 1, r
    assert "holds 2 lines for this id" in r.stderr and "nothing was deleted" in r.stderr, r
    assert {p: p.read_bytes() for p in before} == before


def hand_unregister(folder: Path, pid: str) -> None:
    """What a hand edit leaves: `pid`'s registration line gone from the journal, their row from participants.csv."""
    journal = folder / "journal.jsonl"
    journal.write_bytes(b"".join(line for line in journal.read_bytes().splitlines(keepends=True)
                                 if not (b'"ParticipantRegistered"' in line and f'"{pid}"'.encode() in line)))
    table = folder / "participants.csv"
    table.write_text("".join(r for r in table.read_text().splitlines(keepends=True) if not r.startswith(f"{pid},")))


def exported_inside(cli, folder: Path, tmp_path: Path) -> str:
    assert cli("participant", "export", folder, "p02").returncode == 0  # exports/p02.zip, and a journal line
    return "other journal lines, exports/"


def exported_outside(cli, folder: Path, tmp_path: Path) -> str:
    assert cli("participant", "export", folder, "p02", "-o", tmp_path / "out" / "p02.zip").returncode == 0
    return "other journal lines"  # ParticipantExported names p02; no file of the folder does


def a_recording(cli, folder: Path, tmp_path: Path) -> str:
    (folder / "recordings" / "thesis-ch7-p02-phase1-g1.mcap").write_bytes(b"")  # the name is the record
    return "recordings/"


def a_policy(cli, folder: Path, tmp_path: Path) -> str:
    (folder / "policies" / "thesis-ch7-p02-phase1-g1-r1.policy.json").write_bytes(b"{}")
    return "policies/"


@pytest.mark.parametrize("record", [exported_inside, exported_outside, a_recording, a_policy])
def test_an_id_any_record_of_the_folder_shows_is_never_given_again(pairplay_cli, tmp_path, record):
    """p02 registered without a name (no key-file line), a record of it left, then its registration and its
    participants.csv row removed by hand: the next register gave p02 again (the journal, participants.csv and the
    key file were the only records read); status says where the id is and that it is not registered."""
    folder, key = a_study(pairplay_cli, tmp_path)
    r = pairplay_cli("protocol", "register", folder, "--count", "2")
    assert r.stdout.split() == ["p01", "p02"], r
    where = record(pairplay_cli, folder, tmp_path)
    hand_unregister(folder, "p02")
    assert register(pairplay_cli, folder, "Carol") == "p03"  # was p02
    assert key_ids(key) == ["p03"]
    r = pairplay_cli("protocol", "status", folder)
    assert r.returncode == 0 and (f"p02: not registered in the journal, but named in {where}: the id is not given "
                                  "again") in r.stdout.splitlines(), r


def test_an_id_only_in_the_key_file_after_a_hand_edit_is_never_given_again(pairplay_cli, tmp_path):
    """The brief's case: Bob's registration and participants.csv row removed by hand, his key-file line left."""
    folder, key = a_study(pairplay_cli, tmp_path)
    assert [register(pairplay_cli, folder, n) for n in ("Alice", "Bob")] == ["p01", "p02"]
    hand_unregister(folder, "p02")
    r = pairplay_cli("protocol", "status", folder)
    assert r.returncode == 0 and ("p02: in the key file only: not registered (a crash cut its registration, or a "
                                  "hand edit): no data here; the id is not given again") in r.stdout.splitlines(), r
    assert register(pairplay_cli, folder, "Carol") == "p03"
    assert key_ids(key) == ["p01", "p02", "p03"]


def test_status_beside_an_unreachable_key_file_says_so_and_lists_the_other_records(pairplay_cli, tmp_path):
    """status only reads: a key file on an unmounted drive is said in one line, not raised, and the ids the other
    records show are still listed (the console's state says the same: `StudyData.id_notes`)."""
    folder, key = a_study(pairplay_cli, tmp_path)
    r = pairplay_cli("protocol", "register", folder, "--count", "2")
    assert r.returncode == 0, r
    a_recording(pairplay_cli, folder, tmp_path)
    hand_unregister(folder, "p02")
    key.unlink()
    r = pairplay_cli("protocol", "status", folder)
    assert r.returncode == 0 and r.stderr == "", r
    lines = r.stdout.splitlines()
    assert lines[0].startswith("the ids of the key file are not checked here: the key file is not there (an "
                               "unmounted drive?)") and str(key) in lines[0], r
    assert lines[1] == "p02: not registered in the journal, but named in recordings/: the id is not given again", r
