"""One writer per study folder, and the study file fixed once the study is created (a new user's trial).

Real processes: a `python -m pairplay protocol serve` holds its folder; every other verb that writes the folder
(protocol serve, pilot, register, mark-invalid; participant export, delete; report) is refused at once in
one line naming the folder and the holder, and writes nothing (the trial: two servers gave `p05` to Carla
and to Dieter; `protocol register` beside a server did the same; a deletion beside a server was undone
from its memory); `protocol status` reads beside it (those commands are processes forked from one
that imported pairplay, conftest's pairplay_cli, all at once: each is refused or reads); the kernel drops the lock of a killed server. In a
process, a StudyData never writes from a stale copy of the journal. A study.toml edited in the folder is
refused by every verb that reads the folder (the trial's pilot played 2-round games beside 5-round ones,
its report left games out with exit 0).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from pairplay.replay.studydata import StudyData, StudyDataError
from pairplay.schemas import journal as j

STUDY = Path(__file__).parent / "data" / "pilot-study.toml"


@pytest.fixture
def pairplay(pairplay_cli):
    """`pairplay(*args)`: a whole process of its own per command, forked from one that imported pairplay
    (conftest's pairplay_cli): these tests are of what the verbs do beside a holder, not of a start-up;
    the server that holds the folder is a `python -m pairplay` of its own (serving)."""
    return pairplay_cli


def all_at_once(pairplay, commands: dict[str, list[str]]) -> dict[str, subprocess.CompletedProcess]:
    """The commands run side by side (each is refused or only reads: none waits for another)."""
    with ThreadPoolExecutor(len(commands)) as pool:
        return dict(zip(commands, pool.map(lambda args: pairplay(*args), commands.values())))


def a_study(tmp_path: Path, registered: int = 2) -> StudyData:
    data = StudyData.create(tmp_path / "study", STUDY, key_file=tmp_path / "keys.csv")
    for n in range(registered):
        data.register("phase1", f"Person {n + 1}")
    return data


def serving(folder: Path) -> subprocess.Popen:
    """A `protocol serve` of `folder` once it has printed its console (it holds the folder then); its URL is
    `proc.console_url`."""
    proc = subprocess.Popen([sys.executable, "-m", "pairplay", "protocol", "serve", str(folder)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ, PYTHONUNBUFFERED="1"))
    err: list[str] = []
    proc.err = err  # its stderr's lines, read as they come (whole once `proc.err_read` has ended)
    proc.err_read = threading.Thread(target=lambda: err.extend(proc.stderr), daemon=True)
    proc.err_read.start()
    line = ""
    while "experimenter console:" not in line:
        line = proc.stdout.readline()
        if not line:
            proc.kill()
            proc.wait()
            pytest.fail(f"serve ended before its console: {''.join(err)}")
    threading.Thread(target=lambda: proc.stdout.read(), daemon=True).start()
    proc.console_url = line.split("experimenter console:", 1)[1].strip()
    return proc


def stopped(proc: subprocess.Popen) -> None:
    proc.send_signal(signal.SIGTERM)
    proc.wait(30)


def files_of(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and p.name != ".pairplay-lock"}


def test_a_second_writer_beside_a_running_server_is_refused_in_one_line_and_writes_nothing(tmp_path, pairplay):
    data = a_study(tmp_path)
    folder = data.folder
    before, keys = files_of(folder), (tmp_path / "keys.csv").read_bytes()
    server = serving(folder)
    try:
        writers = {
            "protocol serve": ["protocol", "serve", str(folder)],
            "protocol register": ["protocol", "register", str(folder), "--name", "Dieter"],
            "protocol pilot": ["protocol", "pilot", str(folder), "--personas", "blind,deaf"],
            "protocol mark-invalid": ["protocol", "mark-invalid", str(folder), "pilot-p01-phase1-g1", "--reason", "x"],
            "participant export": ["participant", "export", str(folder), "p01"],
            "participant delete": ["participant", "delete", str(folder), "p02", "--yes"],
            "report": ["report", str(folder)],
        }
        # a reader runs beside the writer (and beside the refused ones)
        ran = all_at_once(pairplay, {**writers, "status": ["protocol", "status", str(folder)]})
        for verb in writers:
            done = ran[verb]
            lines = done.stderr.strip().splitlines()
            assert done.returncode == 2 and len(lines) == 1, (verb, done.returncode, done.stderr)
            assert lines[0].startswith(f"pairplay {verb}: another pairplay writes this study folder: protocol serve "
                                       f"(pid {server.pid}, since "), (verb, lines)
            assert lines[0].endswith(f"({folder})"), (verb, lines)  # the folder, as given
            assert "Traceback" not in done.stderr
        status = ran["status"]
        assert status.returncode == 0 and "p01: phase1 game 1" in status.stdout, status.stderr
        assert files_of(folder) == before  # nothing written: no second p03, p02 not deleted, no report
        assert (tmp_path / "keys.csv").read_bytes() == keys
    finally:
        stopped(server)
    # the server's lock went with it: the next writer works
    done = pairplay("protocol", "register", str(folder), "--name", "Dieter")
    assert done.returncode == 0 and done.stdout.strip() == "p03", done.stderr
    assert (tmp_path / "keys.csv").read_text().splitlines()[-1].startswith("p03,Dieter,")  # then its study


def test_a_killed_server_leaves_no_stale_lock(tmp_path, pairplay):
    data = a_study(tmp_path, registered=0)
    server = serving(data.folder)
    server.kill()  # SIGKILL: no handler runs; the kernel drops the lock
    server.wait(30)
    done = pairplay("protocol", "register", str(data.folder), "--count", "2")
    assert done.returncode == 0 and done.stdout.split() == ["p01", "p02"], done.stderr


def test_a_writer_in_a_process_is_refused_beside_a_writer_that_holds_the_folder(tmp_path):
    a_study(tmp_path, registered=0)
    with StudyData(tmp_path / "study", writer="protocol serve") as holder:
        other = StudyData(tmp_path / "study")  # a reader may open it
        with pytest.raises(StudyDataError, match=r"another pairplay writes this study folder: protocol serve \(pid "
                                                 rf"{os.getpid()}, since "):
            other.register("phase1", "Dieter")
        with pytest.raises(StudyDataError, match="another pairplay writes"):
            StudyData(tmp_path / "study", writer="protocol register")
        assert holder.register("phase1", "Carla") == "p01"
    assert StudyData(tmp_path / "study", writer="protocol register").register("phase1") == "p02"


def test_a_stale_copy_of_the_journal_never_writes(tmp_path):
    """Two objects on one folder (two servers before the lock; a pairplay without it): the second one's memory
    said p01 was free and the key file got `p01,Carla` and `p01,Dieter`; a deletion was undone by the other's
    tables. Now the stale one refuses, and nothing is written from it."""
    data = a_study(tmp_path, registered=0)
    stale = StudyData(data.folder)
    assert data.register("phase1", "Carla") == "p01"
    with pytest.raises(StudyDataError, match="journal.jsonl was changed by another process since this one read it"):
        stale.register("phase1", "Dieter")
    assert [line.rsplit(",", 1)[0] for line in (tmp_path / "keys.csv").read_text().splitlines()[1:]] == ["p01,Carla"]
    assert [e.participant for e in data.read_journal() if isinstance(e, j.ParticipantRegistered)] == ["p01"]
    data.register("phase1")
    stale = StudyData(data.folder)
    data.delete_participant("p01")
    with pytest.raises(StudyDataError, match="changed by another process"):
        stale.write_tables()  # it would write p01 back into participants.csv
    assert "p01" not in (data.folder / "participants.csv").read_text()
    assert StudyData(data.folder).register("phase1") == "p03"  # a fresh read goes on (p01, p02 given: no reuse, no skip)


EDITED = {"rounds": ("rounds = 2", "rounds = 5"), "a comment": ("# Phase 1 (7.2)", "# phase one")}


@pytest.mark.parametrize("edit", sorted(EDITED))
def test_a_study_file_edited_in_the_folder_is_refused_by_every_verb_that_reads_it(tmp_path, edit, pairplay):
    data = a_study(tmp_path)
    toml = data.folder / "study.toml"
    original = toml.read_bytes()
    old, new = EDITED[edit]
    assert old.encode() in original
    toml.write_bytes(original.replace(old.encode(), new.encode(), 1))
    before = files_of(data.folder)
    ran = all_at_once(pairplay, {"status": ["protocol", "status", str(data.folder)],
                                 "register": ["protocol", "register", str(data.folder)],
                                 "pilot": ["protocol", "pilot", str(data.folder), "--personas", "blind,deaf"],
                                 "report": ["report", str(data.folder)]})
    for args, done in ran.items():
        lines = done.stderr.strip().splitlines()
        assert done.returncode == 2 and len(lines) == 1, (args, done.returncode, done.stderr)
        assert "study.toml" in lines[0] and "changed since the study was created" in lines[0], lines
        assert "put back the file the study was created with, or make a new study folder" in lines[0]
    assert files_of(data.folder) == before  # no game played under the edited file, no report, no export
    with pytest.raises(StudyDataError, match="changed since the study was created"):
        StudyData(data.folder)
    # a participant's export and erasure do not wait for the file to be put back (trial16: an unrelated edit
    # stopped a deletion); the edit is said, on stderr
    for args in (["export", "p01"], ["delete", "p02", "--yes"]):
        done = pairplay("participant", args[0], str(data.folder), *args[1:])
        lines = done.stderr.strip().splitlines()
        assert done.returncode == 0 and len(lines) == 1, (args, done.stderr)
        assert lines[0].startswith(f"pairplay participant {args[0]}: the study file changed since the study was created")
        assert lines[0].endswith("(it needs only the journal)"), lines
    assert (data.folder / "exports" / "p01.zip").is_file() and "p02" not in (data.folder / "participants.csv").read_text()
    toml.write_bytes(original)  # put back: the study goes on
    done = pairplay("protocol", "status", str(data.folder))
    assert done.returncode == 0, done.stderr


def test_a_writer_says_the_edited_study_file_before_it_meets_another_writers_lock(tmp_path, pairplay):
    """The edit is the user's mistake: said as such beside a writer that holds the folder, not "another pairplay
    writes this study folder" (the test above, under load: `register` met the lock of the pilot started beside it,
    which was itself about to refuse the edit). A writer checks the study file before it takes the lock."""
    data = a_study(tmp_path)
    server = serving(data.folder)  # it holds the folder from here; the file is edited beside it
    toml = data.folder / "study.toml"
    toml.write_bytes(toml.read_bytes().replace(b"rounds = 2", b"rounds = 5", 1))
    try:
        ran = all_at_once(pairplay, {
            "protocol register": ["protocol", "register", str(data.folder)],
            "protocol pilot": ["protocol", "pilot", str(data.folder), "--personas", "blind,deaf"],
            "protocol mark-invalid": ["protocol", "mark-invalid", str(data.folder), "pilot-p01-phase1-g1",
                                      "--reason", "x"],
            "protocol serve": ["protocol", "serve", str(data.folder)],
            "report": ["report", str(data.folder)]})
    finally:
        stopped(server)
    for verb, done in ran.items():
        lines = done.stderr.strip().splitlines()
        assert done.returncode == 2 and len(lines) == 1, (verb, done.returncode, done.stderr)
        assert lines[0].startswith(f"pairplay {verb}: changed since the study was created"), (verb, lines)


def test_a_journal_without_the_study_files_hash_is_read_as_it_was(tmp_path):
    """Every journal `protocol init` wrote records the hash (the field is required since the first journal);
    one without it (an empty hash: made by hand) has nothing to check against and is read as before."""
    data = a_study(tmp_path, registered=1)
    journal = data.folder / "journal.jsonl"
    lines = journal.read_bytes().splitlines(keepends=True)
    first = j.decode_line(lines[0])
    journal.write_bytes(j.encode_line(j.StudyCreated(study=first.study, study_file_sha256="",
                                                     software_version=first.software_version,
                                                     time_ns=first.time_ns)) + b"".join(lines[1:]))
    (data.folder / "study.toml").write_bytes((data.folder / "study.toml").read_bytes() + b"\n# a note\n")
    assert list(StudyData(data.folder).state.participants) == ["p01"]


def test_a_game_whose_process_died_does_not_stop_the_participants_deletion_but_a_running_one_does(tmp_path):
    """trial16: `protocol pilot` SIGKILLed mid-game left a GameStarted without its GameEnded, and `participant
    delete` refused for ever ("p02 has a game running ... abort it first"): no verb could end that game, and the
    participant could not be erased. A writer holds the folder's lock, so no other process can run a game of it:
    only a game this process started and has not ended is running."""
    data = a_study(tmp_path, registered=2)
    started = dict(phase="phase1", game=1, recording="recordings/x.mcap")
    with StudyData(data.folder, writer="protocol pilot") as died:  # its process SIGKILLed: no GameEnded
        died.append(j.GameStarted(participant="p01", session="s-p01", **started))
    with StudyData(data.folder, writer="participant delete") as now:
        assert now.state.games["s-p01"].ended is None  # still "running" in the journal's words
        now.append(j.GameStarted(participant="p02", session="s-p02", **started))  # this process's own game
        with pytest.raises(StudyDataError, match=r"^p02 has a game running \(s-p02\): abort it first \(.*study\)$"):
            now.delete_participant("p02")
        now.delete_participant("p01")
    assert "p01" not in (data.folder / "participants.csv").read_text()
