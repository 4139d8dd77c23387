"""Every verb that reads a recording says the same of one that holds no session (a new user's trial, 2026-12-01:
`pairplay recover` of a cut file of pairplay events with no SessionStarted copied it, exit 0, "its SessionStarted is
not in it", while `replay --verify` of the same file refused it, exit 2; `report` of a study whose recordings hold
none said only "no completed, valid game", naming the resolved folder).

Rule checked: exit 2, nothing on stdout, nothing written, and one line on stderr, `pairplay <verb>: <what> (<the
path as typed>)`, the what in the reader's words (replay/reader.py `EventLog.no_session`: the reader decides what a
recording holds). Real parts: MCAP files written by mcap's and the recorder's writers, cut and damaged on disk as a
crash or a disk would; a study folder played by a scripted persona over a real loopback bus; the real verbs."""

from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

import pytest
from mcap.writer import Writer

from damageutil import damage, small_chunked_session

from pairplay.cli.main import main
from pairplay.replay.mcapscan import scan
from pairplay.replay.reader import read_log
from pairplay.replay.writer import EventLogWriter
from pairplay.schemas.envelope import stamped
from pairplay.schemas.events import ServiceStarted, encode_event
from pairplay.schemas.keys import event_key

STUDY = Path(__file__).parent / "data" / "pilot-study.toml"


def _other_kinds(path: Path) -> Path:
    """A whole pairplay recording of events of other kinds than SessionStarted (services that started, in small
    chunks), as a session that never started leaves it."""
    w = EventLogWriter(path, chunk_size=512)
    for i in range(60):
        e = stamped(ServiceStarted(service="learner", version="x"), session="s1", source="learner", seq=i + 1,
                    time_ns=10 + i)
        w.write(event_key("s1", "learner", "ServiceStarted"), encode_event(e), log_time_ns=10 + i)
    w.close()
    return path


def _make(kind: str, path: Path) -> Path:
    """A recording holding no session, of `kind`."""
    if kind in ("empty", "schema only"):  # a whole MCAP file (summary, footer) with no message
        with open(path, "wb") as f:
            w = Writer(f)
            w.start(profile="", library="another recorder")
            if kind == "schema only":
                w.register_schema("s", "jsonschema", b"{}")
            w.finish()
    elif kind == "other kinds":
        _other_kinds(path)
    elif kind == "other kinds, cut":  # cut after its last chunk, as a crash leaves it: a cut loses an end, no start
        _other_kinds(path)
        last = scan(path).chunks[-1]
        path.write_bytes(path.read_bytes()[:last.offset + last.length])
    elif kind == "start lost to damage":  # the chunk holding its SessionStarted fails its CRC
        small_chunked_session(path, "d1")
        damage(path, "chunk", "SessionStarted")
    assert read_log(path).no_session, kind
    return path


KINDS = ["empty", "schema only", "other kinds", "other kinds, cut", "start lost to damage"]
VERBS = {"recover": ["recover", "F"], "replay": ["replay", "F", "--speed", "max"],
         "replay --verify": ["replay", "F", "--verify"], "rebuild": ["rebuild", "F", "--out", "out"],
         "view": ["view", "--recording", "F", "--out", "v.rrd"], "counterfactual": ["counterfactual", "F", "--out", "cf"]}


def _snapshot(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else "dir"
            for p in sorted(root.rglob("*"))}


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("verb", list(VERBS))
def test_every_verb_refuses_a_recording_holding_no_session_in_the_same_words(tmp_path, monkeypatch, capsys, verb, kind):
    """recover of a cut or damaged file of events with no SessionStarted wrote a copy and exit 0 (before); every verb
    now refuses it as replay did, in the reader's words, naming the file as typed."""
    monkeypatch.chdir(tmp_path)
    _make(kind, tmp_path / "rec.mcap")
    words = read_log("rec.mcap").no_session
    before = _snapshot(tmp_path)
    code = main([a.replace("F", "rec.mcap") if a == "F" else a for a in VERBS[verb]])
    out, err = capsys.readouterr()
    assert (code, out, err) == (2, "", f"pairplay {verb.split()[0]}: {words} (rec.mcap)\n")
    assert _snapshot(tmp_path) == before  # nothing written


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> Path:
    """A study folder of one phase, one game of one round, played by a scripted persona (protocol pilot)."""
    root = tmp_path_factory.mktemp("nosession-study")
    text = STUDY.read_text()
    text = text[:text.index("# Phase 2")] + text[text.index("# The questions behind"):]  # phase 1 alone
    (root / "one.toml").write_text(text.replace("games = 2\nrounds = 2", "games = 1\nrounds = 1", 1))
    for argv in (["protocol", "init", str(root / "st"), "--study", str(root / "one.toml"), "-q"],
                 ["protocol", "register", str(root / "st"), "-q"],
                 ["protocol", "pilot", str(root / "st"), "--personas", "blind", "-q"]):
        assert main(argv) == 0, argv
    return root / "st"


@pytest.mark.parametrize("kind", KINDS)
def test_the_report_of_a_study_whose_recordings_hold_no_session_says_why_naming_the_folder_as_typed(
        study, tmp_path, monkeypatch, capsys, kind):
    """Before: "pairplay report: /tmp/.../st: no completed, valid game to report on": the folder resolved, and not a
    word of why. Now the first game left out and why, in the reader's words, and the folder as typed."""
    monkeypatch.chdir(tmp_path)
    shutil.copytree(study, "st")
    [rec] = list(Path("st/recordings").glob("*.mcap"))
    _make(kind, rec)
    words = read_log(rec).no_session
    capsys.readouterr()
    assert main(["report", "st"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err == (f"pairplay report: no completed, valid game to report on: {rec.name[:-5]} "
                                 f"(recording {words}) left out (st)\n"), err
    assert not Path("st/report").exists()
