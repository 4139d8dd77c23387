"""A verb whose output lands inside a study folder takes the folder's writer lock, as every writer of it does.

A new user's trial: `pairplay view --recording R`, R a game's recording in a people's study folder beside a
running `protocol serve`, wrote R's .rrd into the folder outside its lock (pairplay/folderlock.py: one writer
per study folder), unjournaled: the deletion erases a file named after the game beside its recording by itself
(replay/copies.py `erased_anyway`), so no journal line was needed and none of the copy checks ran. The same
held for `recover`, whose copy goes beside the recording too (the other verbs' outputs inside a study folder are
refused before any work: cli/args.py `check_study_folders`). Real processes: a real server holds the folder; each verb is refused at once in one line
naming the holder and writes nothing; once the server has stopped, the view is written and the lock is free.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from test_journal import complete_recording, journal_of, pick, start
from test_study_guard import a_study, files_of, pairplay, serving, stopped

from pairplay.cli.main import main

SAMPLE = Path(__file__).resolve().parents[1] / "recordings" / "samples" / "sim-helmut-fmt2.mcap"


@pytest.fixture
def study(tmp_path):
    """A people's study folder holding a game's recording (and a cut one, for recover), not yet served."""
    folder = a_study(tmp_path).folder
    (folder / "recordings").mkdir(exist_ok=True)
    rec = folder / "recordings" / "pilot-p01-phase1-g1.mcap"
    shutil.copy(SAMPLE, rec)
    cut = folder / "recordings" / "pilot-p02-phase1-g1.mcap"
    cut.write_bytes(SAMPLE.read_bytes()[: SAMPLE.stat().st_size * 2 // 3])
    return folder, rec, cut


def a_stale_journal_beside(folder: Path, tmp_path: Path) -> Path:
    """A complete recording in the study's recordings/ with a stale journal beside it (test_journal's): what
    `recover --discard-journal` removes."""
    events = [start()] + [pick(s) for s in range(1, 6)]
    (tmp_path / "scratch").mkdir()
    made = complete_recording(tmp_path / "scratch", events)
    journal = journal_of(made, events)
    for f in (made, journal):
        shutil.move(f, folder / "recordings" / f.name)
    return folder / "recordings" / made.name


def test_a_verb_writing_into_a_served_study_folder_is_refused_and_writes_nothing(study, tmp_path, pairplay):
    folder, rec, cut = study
    stale = a_stale_journal_beside(folder, tmp_path)
    verbs = {
        "view": ["view", "--recording", str(rec)],  # -> beside it: recordings/<game>.rrd
        "recover": ["recover", str(cut)],  # -> beside it
    }
    extra = [["view", "--recording", str(rec), "--out", str(rec.with_suffix(".rrd"))],  # the same place, named
             ["recover", str(cut), "-o", str(cut.with_name("pilot-p02-phase1-g1.whole.mcap"))],
             ["recover", str(stale), "--discard-journal"]]  # removing a file writes the folder too
    before = files_of(folder)
    server = serving(folder)
    try:
        for verb, args in [*verbs.items(), *((a[0], a) for a in extra)]:
            done = pairplay(*args, "--quiet")
            lines = done.stderr.strip().splitlines()
            assert done.returncode == 2 and len(lines) == 1 and "Traceback" not in done.stderr, (verb, done.stderr)
            assert lines[0].startswith(f"pairplay {verb}: another pairplay writes this study folder: protocol serve "
                                       f"(pid {server.pid}, since "), (verb, lines)
            assert "would write into it" in lines[0] and lines[0].endswith(f"({folder})"), (verb, lines)
        assert files_of(folder) == before  # no .rrd, no recovered copy, the journal not removed
        assert not list(folder.rglob("*.rrd"))
    finally:
        stopped(server)
    done = pairplay("view", "--recording", str(rec), "--quiet")  # the server's lock gone: the view is written
    assert done.returncode == 0 and rec.with_suffix(".rrd").is_file(), done.stderr
    assert (folder / ".pairplay-lock").read_bytes() == b""  # and its own lock released


def test_a_verb_writing_into_a_study_folder_waits_for_a_short_holder_then_writes(study):
    """A short holder (a register, an export) is waited for, as every other writer of the folder waits for it
    (tests/test_study_lock_wait.py): `recover` of a game's recording in the folder was refused at once."""
    import os
    import subprocess
    import sys

    from pairplay import folderlock
    folder, rec, cut = study
    fd = folderlock.take(folder, "participant export")  # this process holds the folder, as a short verb
    recover = subprocess.Popen([sys.executable, "-m", "pairplay", "recover", str(cut), "--quiet"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        said = recover.stderr.readline()  # it waits, and says so, before the holder ends
        assert said.startswith("pairplay recover: waiting up to ") and \
            f"participant export (pid {os.getpid()}, since " in said, said
        assert recover.poll() is None
    finally:
        folderlock.release(fd)
    out, err = recover.communicate(timeout=60)
    assert recover.returncode == 0 and err == "", (out, err)
    assert (folder / ".pairplay-lock").read_bytes() == b""  # its own lock released


def test_a_verb_run_in_process_releases_the_folders_lock_however_it_ends(study, capsys, pairplay):
    """The lock a verb's output took is released when it ends (cli/main.py), refused or not: a second verb in the
    same process (a test, a script calling main) is not refused by the first one's lock."""
    folder, rec, cut = study
    assert main(["view", "--recording", str(rec), "--quiet"]) == 0
    assert main(["view", "--recording", str(rec), "--quiet"]) == 2  # exists: refused (before its lock is taken)
    assert "exists" in capsys.readouterr().err
    assert main(["view", "--recording", str(rec), "--quiet", "--force"]) == 0
    assert main(["recover", str(cut), "--quiet"]) == 0
    assert (folder / ".pairplay-lock").read_bytes() == b""
    done = pairplay("protocol", "register", str(folder), "--name", "Dieter")  # another process may write it now
    assert done.returncode == 0, done.stderr
