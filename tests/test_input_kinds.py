"""Only a regular file (or a link to one) is read as an input: a named pipe, a device, a socket where a verb reads
a recording, a policy, a grid, a study file or a config is refused in one line naming the path and what it is,
exit 2, before it is opened (pairplay/inputs.py).

A new user's trial (trial26): a FIFO given as an input made `rebuild`, `replay --verify`, `recover` and `combine`
block silently until a signal (opening a FIFO for reading waits for a writer). Each verb that reads a file the user
names meets it: one shared check (pairplay/inputs.py `check_input`), called by every reader of such a file; a
pipe inside a folder given as input (`combine rebuilt/`; a study folder's journal, key file, game recordings; a
recording's journal beside it) is said alike by the reader of that file.
Each run has a timeout only as a net: on main's code the pipes' runs hung until it.
"""

from __future__ import annotations

import os
import shutil
import socket
from pathlib import Path

import pytest
from test_output_kinds import make_inputs

GAME = "study/recordings/one-p01-phase1-g1.mcap"  # the pilot's game
SESSION = ("session", "--participant", "sim:blind", "--rounds", "2", "--out", "rec", "--session", "s1")

# verb -> its arguments, IN standing for the input made special (a name ending as the verb expects its input)
VERBS = {
    "rebuild": ("rebuild", "IN.mcap", "--out", "rb", "--no-plot"),
    "replay --verify": ("replay", "IN.mcap", "--verify"),
    "replay": ("replay", "IN.mcap", "--speed", "max"),
    "view --recording": ("view", "--recording", "IN.mcap", "--out", "v.rrd"),
    "counterfactual": ("counterfactual", "IN.mcap", "--fit-only", "--out", "cf"),
    "counterfactual --fit-also": ("counterfactual", "R.mcap", "--fit-also", "IN.mcap", "--fit-only", "--out", "cf"),
    "counterfactual --policy": ("counterfactual", "R.mcap", "--policy", "fixed:IN.json", "--seeds", "2",
                                "--out", "cf"),
    "recover": ("recover", "IN.mcap", "-o", "fixed.mcap"),
    "combine": ("combine", "IN.json", "-o", "m.json"),
    "profile": ("profile", "IN.json"),
    "session --policy": (*SESSION, "--algorithm", "fixed", "--policy", "IN.json"),
    "report --reference": ("report", "study", "--reference", "IN.json", "--out", "rep"),
    "sweep": ("sweep", "IN.toml", "--out", "sw", "-q"),
    "protocol check": ("protocol", "check", "IN.toml"),
    "protocol init --study": ("protocol", "init", "pf", "--study", "IN.toml"),
    "session --robot-config": (*SESSION, "--robot", "virtual", "--robot-config", "IN.json"),
    "session --calibration": (*SESSION, "--robot", "virtual", "--calibration", "IN.json"),
    "session --zenoh-config": (*SESSION, "--zenoh-config", "IN.json5"),
    "lab --certfile": ("lab", "--participant", "human:p1", "--certfile", "IN.pem", "--keyfile", "key.pem"),
    "protocol serve --keyfile": ("protocol", "serve", "study", "--certfile", "cert.pem", "--keyfile", "IN.pem"),
}


@pytest.fixture(scope="module")
def template(tmp_path_factory, pairplay_cli) -> Path:
    """A folder with what the verbs read besides their special input: a recording and a cut one, rebuilt policies,
    a study folder with one participant's game played (a pilot), a certificate's and a key's (regular) files."""
    root = tmp_path_factory.mktemp("inkinds")
    make_inputs(root, pairplay_cli)
    for args in (("protocol", "register", "study"), ("protocol", "pilot", "study", "--personas", "blind")):
        r = pairplay_cli(*args, cwd=root, timeout=300)
        assert r.returncode == 0, (args, r.stderr)
    assert (root / GAME).is_file()
    (root / "cert.pem").write_text("not read: its key is refused first\n")
    (root / "key.pem").write_text("not read: its certificate is refused first\n")
    return root


def _make(kind: str, path: Path) -> tuple[Path, str]:
    """Make a `kind` of input at `path` (or name one: /dev/null); (the path the verb is given, what its refusal
    calls it)."""
    if kind == "fifo":
        os.mkfifo(path)
        return path, "is a named pipe (FIFO), not a regular file"
    if kind == "socket":
        s = socket.socket(socket.AF_UNIX)
        s.bind(str(path))
        s.close()
        return path, "is a socket, not a regular file"
    if kind == "link to a fifo":
        os.mkfifo(path.with_name("pipe"))
        path.symlink_to("pipe")
        return path, "is a symbolic link to a named pipe (FIFO), not a regular file"
    if kind == "folder":
        path.mkdir()
        return path, "a folder"
    if kind == "/dev/null":
        return Path("/dev/null"), "is a character device, not a regular file"
    assert kind == "/dev/stdin"  # a link to what the command's stdin is: a pipe, a terminal or /dev/null
    return Path("/dev/stdin"), "not a regular file"


def _files(root: Path) -> set[str]:
    return {p.relative_to(root).as_posix() for p in root.rglob("*")}


def _refused(r, said: str, given: Path, before: set[str], root: Path, args) -> None:
    """Exit 2, one line naming the input and what it is, no traceback, nothing written."""
    assert r.returncode == 2 and r.stderr.count("\n") == 1, (args, r.returncode, r.stdout, r.stderr)
    line = r.stderr.replace(str(root), "ROOT")  # what it says, not the words of the test's folder's name
    assert said in line and given.name in line, (args, r.stderr)
    assert "Traceback" not in r.stderr and not r.stdout, (args, r.stdout)
    assert _files(root) == before, (args, _files(root) ^ before)


def _run(verb: str, kind: str, template: Path, tmp_path: Path, pairplay_cli, said_instead: str = "") -> None:
    root = tmp_path / "w"
    shutil.copytree(template, root, symlinks=True)
    args = VERBS[verb]
    named = next(a for a in args if "IN." in a)
    given, said = _make(kind, root / named.split(":")[-1])
    said = said_instead or said
    args = tuple(a.replace(named.split(":")[-1], str(given)) if a == named else a for a in args)
    before = _files(root)
    r = pairplay_cli(*args, cwd=root, timeout=90)  # a net: main's code waited for a writer of the pipe
    _refused(r, said, given, before, root, args)


@pytest.mark.parametrize("verb", VERBS)
def test_a_pipe_given_as_an_input_is_refused_in_one_line(verb, template, tmp_path, pairplay_cli):
    _run(verb, "fifo", template, tmp_path, pairplay_cli)


@pytest.mark.parametrize("verb", VERBS)
def test_a_folder_given_as_an_input_file_is_one_line(verb, template, tmp_path, pairplay_cli):
    """A folder where a file is read is said in one line naming it, as a pipe is (every verb's own words); combine
    and profile take a folder of policies, and one holding none is said so."""
    taken = "holds no policy files" if verb in ("combine", "profile") else ""
    _run(verb, "folder", template, tmp_path, pairplay_cli, said_instead=taken)


@pytest.mark.parametrize("kind", ["socket", "link to a fifo", "/dev/null", "/dev/stdin"])
@pytest.mark.parametrize("verb", ["rebuild", "combine", "sweep", "protocol check"])
def test_every_kind_of_special_input_is_refused(verb, kind, template, tmp_path, pairplay_cli):
    _run(verb, kind, template, tmp_path, pairplay_cli)


def test_a_link_to_a_regular_file_is_read(template, tmp_path, pairplay_cli):
    """Links are followed for inputs: a link to a recording is the recording."""
    root = tmp_path / "w"
    shutil.copytree(template, root, symlinks=True)
    (root / "L.mcap").symlink_to("R.mcap")
    r = pairplay_cli("rebuild", "L.mcap", "--out", "rb", "--no-plot", cwd=root)
    assert r.returncode == 0, r.stderr
    assert (root / "rb" / "L.policy.json").is_file()


@pytest.mark.parametrize("verb", ["combine", "profile"])
def test_a_pipe_inside_a_folder_given_as_input_is_refused(verb, template, tmp_path, pairplay_cli):
    """`combine rebuilt/` reads every *.json below it: a pipe named x.json there is refused by name (a mistake to
    say, not a file to skip silently), not waited on."""
    root = tmp_path / "w"
    shutil.copytree(template, root, symlinks=True)
    os.mkfifo(root / "rebuilt" / "x.json")
    before = _files(root)
    args = ("combine", "rebuilt/", "-o", "m.json") if verb == "combine" else ("profile", "rebuilt/")
    r = pairplay_cli(*args, cwd=root, timeout=90)
    _refused(r, "is a named pipe (FIFO), not a regular file", root / "rebuilt" / "x.json", before, root, args)


@pytest.mark.parametrize("verb", ["report", "participant export"])
def test_a_pipe_at_a_study_games_recording_is_said_not_waited_on(verb, template, tmp_path, pairplay_cli):
    """A study folder's recordings are read by `report` and zipped by `participant export`: a pipe standing at a
    game's recording was "recording missing" to the report, and left out of the export silently (rc 0)."""
    root = tmp_path / "w"
    shutil.copytree(template, root, symlinks=True)
    (root / GAME).unlink()
    os.mkfifo(root / GAME)
    before = _files(root)
    args = ("report", "study", "--out", "rep") if verb == "report" else ("participant", "export", "study", "p01",
                                                                          "-o", "p01.zip")
    r = pairplay_cli(*args, cwd=root, timeout=90)
    _refused(r, "is a named pipe (FIFO), not a regular file", root / GAME, before, root, args)


def test_a_pipe_beside_a_recording_as_its_journal_is_said_not_waited_on(template, tmp_path, pairplay_cli):
    """`recover cut.mcap` reads the recorder's journal beside it (cut.mcap.journal): a pipe there is said (the
    journal unread, in recover's words for an unreadable one) and the recording recovered, not waited on."""
    root = tmp_path / "w"
    shutil.copytree(template, root, symlinks=True)
    os.mkfifo(root / "cut.mcap.journal")
    r = pairplay_cli("recover", "cut.mcap", "-o", "fixed.mcap", cwd=root, timeout=90)
    assert r.returncode == 0 and r.stderr.count("\n") == 1, (r.returncode, r.stderr)
    assert "cut.mcap.journal is a named pipe (FIFO), not a regular file" in r.stderr, r.stderr
    assert (root / "fixed.mcap").is_file()


def test_a_pipe_at_a_study_folders_journal_is_named(template, tmp_path, pairplay_cli):
    """A study folder is read from its journal first: a pipe there was "not a study folder (no journal.jsonl)"."""
    root = tmp_path / "w"
    shutil.copytree(template, root, symlinks=True)
    (root / "study" / "journal.jsonl").unlink()
    os.mkfifo(root / "study" / "journal.jsonl")
    before = _files(root)
    r = pairplay_cli("protocol", "status", "study", cwd=root, timeout=90)
    _refused(r, "is a named pipe (FIFO), not a regular file", root / "study" / "journal.jsonl", before, root,
             "protocol status")


def test_a_pipe_at_a_studys_key_file_is_named_not_waited_on(template, tmp_path, pairplay_cli):
    """A study's key file is read before an id is given (`register`): a pipe put in its place was waited on."""
    root = tmp_path / "w"
    shutil.copytree(template, root, symlinks=True)
    r = pairplay_cli("protocol", "init", "keyed", "--study", "one.toml", "--key-file", "keys/k.csv", cwd=root)
    assert r.returncode == 0, r.stderr
    (root / "keys" / "k.csv").unlink()
    os.mkfifo(root / "keys" / "k.csv")
    before = _files(root)
    r = pairplay_cli("protocol", "register", "keyed", "--name", "Ann", cwd=root, timeout=90)
    _refused(r, "is a named pipe (FIFO), not a regular file", root / "keys" / "k.csv", before, root,
             "protocol register")


@pytest.mark.parametrize("name", ["participants.csv", "journal.jsonl.torn-1"])
def test_a_pipe_among_a_study_folders_records_of_ids_is_not_waited_on(name, template, tmp_path, pairplay_cli):
    """`register` reads every record of the ids given (participants.csv, the torn lines `repair` set aside) before
    it gives one: a pipe at participants.csv is named; one named like a torn line's file holds no id and is not
    opened (it was: both waited on the pipe)."""
    root = tmp_path / "w"
    shutil.copytree(template, root, symlinks=True)
    (root / "study" / name).unlink(missing_ok=True)
    os.mkfifo(root / "study" / name)
    before = _files(root)
    r = pairplay_cli("protocol", "register", "study", cwd=root, timeout=90)
    if name == "participants.csv":
        _refused(r, "is a named pipe (FIFO), not a regular file", root / "study" / name, before, root, "register")
    else:
        assert r.returncode == 0 and r.stdout == "p02\n", (r.returncode, r.stdout, r.stderr)
