"""A session id is taken once it has a recording: every verb that starts a new session refuses,
before anything starts, an id whose `<id>.mcap` or any `<id>.<k>.mcap` exists (one line naming the
file and the way out); only a recorder restarted within the same live session continues the file.
Before: `pairplay session --session NAME` over an interrupted NAME's recording continued it into
NAME.1.mcap, the recorder refused the new game's SessionStarted as a repeat and the process hung
for ten minutes."""

import threading

import pytest

from pairplay.cli.main import main
from pairplay.replay.reader import read_log
from pairplay.schemas import events as ev
from pairplay.schemas.session import SessionConfig
from pairplay.services.bus import Bus, BusOptions
from pairplay.services.recorder import Recorder, RecordingExists, check_new_recording, recordings_of
from pairplay.services.session import StartRefused, run_session

from test_recorder import message


def earlier_recording(path, session="dup"):
    """A real (short) recording of an earlier `session`: the recorder's own file, a game's start in it."""
    rec = Recorder(None, session, path)
    cfg = SessionConfig(session=session, participant="sim:ashley", persona="ashley", seed=1, rounds=1)
    key, payload = message(ev.SessionStarted(config=cfg), session=session)
    assert rec.record(key.replace("/r1/", f"/{session}/"), payload, 1)
    rec.close()
    return path


@pytest.mark.parametrize("name", ["dup.mcap", "dup.3.mcap"])
@pytest.mark.parametrize("verb", ["session", "lab"])
def test_a_new_session_over_an_existing_recording_is_refused_before_anything_starts(tmp_path, capsys, name, verb):
    old = earlier_recording(tmp_path / name)
    before = old.read_bytes()
    who = "sim:ashley" if verb == "session" else "human:p1"
    assert main([verb, "--participant", who, "--session", "dup", "--out", str(tmp_path)]) == 2
    out, err = capsys.readouterr()
    assert out == "" and len(err.strip().splitlines()) == 1, err
    assert err.startswith(f"pairplay {verb}: ") and str(old) in err and "--session" in err
    assert ("--force" in err) == (verb == "session")  # a person's recording is never replaced
    assert sorted(p.name for p in tmp_path.iterdir()) == [name] and old.read_bytes() == before


def test_force_replaces_every_earlier_recording_of_the_session(tmp_path, capsys):
    earlier_recording(tmp_path / "dup.mcap")
    earlier_recording(tmp_path / "dup.2.mcap")
    assert main(["session", "--participant", "sim:ashley", "--rounds", "1", "--session", "dup", "--out",
                 str(tmp_path), "--force"]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dup.mcap"]
    log = read_log(tmp_path / "dup.mcap")
    assert log.whole and log.metadata["pairplay.recorder.end"]["session_ended"] == "true"
    assert not any(isinstance(r.event, (ev.RecordingGap, ev.MessageRejected)) for r in log.events)


def test_every_numbered_recording_counts_and_is_found_past_gaps(tmp_path):
    for name in ("s.mcap", "s.2.mcap", "s.10.mcap", "s.x.mcap", "s.1.mcap.tmp", "s2.mcap"):
        (tmp_path / name).write_bytes(b"x")
    assert [p.name for p in recordings_of(tmp_path / "s.mcap")] == ["s.mcap", "s.2.mcap", "s.10.mcap"]
    (tmp_path / "s.mcap").unlink()
    with pytest.raises(RecordingExists) as err:
        check_new_recording(tmp_path / "s.mcap")
    assert str(tmp_path / "s.2.mcap") in err.value.line()
    # a recorder of a new session refuses too (whatever path its caller checked)
    with pytest.raises(RecordingExists):
        Recorder(None, "s", tmp_path / "s.mcap")


def test_a_recorder_run_alone_over_a_recording_of_no_live_session_is_refused(tmp_path, capsys):
    old = earlier_recording(tmp_path / "dup.mcap")
    assert main(["run", "recorder", "--session", "dup", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and str(old) in err and "no live session" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dup.mcap"]


def test_a_refused_session_start_ends_the_session_at_once_instead_of_waiting_for_ever(tmp_path):
    # the old bug's path, on purpose: a recorder that continues an earlier session's file refuses the
    # new game's SessionStarted as a repeat; the game must not wait for picks that cannot come
    earlier_recording(tmp_path / "dup.mcap")
    config = SessionConfig(session="dup", participant="sim:ashley", persona="ashley", seed=1, rounds=20)
    with Bus(BusOptions(mode="peer")) as bus:
        recorder = Recorder(bus, "dup", tmp_path / "dup.mcap", restart=True)
        recorder.start()
        stop = threading.Event()
        thread = threading.Thread(target=recorder.run, args=(stop,), daemon=True)
        thread.start()
        try:
            with pytest.raises(StartRefused) as err:
                run_session(config, tmp_path / "unused.mcap", bus=bus, external=("recorder",), settle_timeout_s=5)
        finally:
            stop.set()
            thread.join(5)
            recorder.close()
    line = err.value.line()
    assert "refused the session's start (a second SessionStarted" in line and "session dup" in line, line


def test_a_study_game_over_a_recording_the_journal_does_not_know_is_refused(tmp_path):
    from pairplay.replay.studydata import StudyData, StudyDataError
    from pairplay.services.protocol import StudyRunner
    from pairplay.services.scripted import ScriptedPlayer

    from test_protocol import STUDY

    data = StudyData.create(tmp_path / "s", STUDY)
    pid = data.register("phase1", consent=True)
    stray = data.folder / "recordings" / f"{data.session_id(pid, 'phase1', 0)}.2.mcap"
    stray.parent.mkdir(parents=True, exist_ok=True)
    stray.write_bytes(b"a copied folder's file")
    journal = (data.folder / "journal.jsonl").read_bytes()
    with Bus(BusOptions()) as bus:
        with pytest.raises(StudyDataError, match="has a recording already") as err:
            StudyRunner(data, bus).run_game(pid, "phase1", 0, ScriptedPlayer("tatiana"))
    assert str(stray) in str(err.value) and stray.read_bytes() == b"a copied folder's file"
    assert (data.folder / "journal.jsonl").read_bytes() == journal  # nothing journaled: the game never started


@pytest.mark.parametrize("verb", ["session", "lab"])
def test_a_made_up_session_id_obeys_the_id_rule_too(verb):
    """`lab --participant human:p.1` (no --session) recorded `p.1-seed0-...mcap`: a made-up id with a `.`,
    which `--session` refuses (it names the recording's files)."""
    from pairplay.cli.args import session_id
    from pairplay.cli.main import build_parser
    from pairplay.cli.session import config_from_args
    argv = [verb, "--participant", "human:p.1"]
    parser, _ = build_parser(argv)
    config = config_from_args(parser.parse_args(argv))
    assert "." not in config.session and config.session.startswith("p_1-seed0-game0-")
    assert session_id(config.session) == config.session


def test_force_keeps_the_earlier_recordings_until_the_new_session_has_started(tmp_path):
    """A new user's trial: `session --force` stopped by Ctrl-C before its game started (it waited for an
    external learner) had already removed the earlier recording; `study --force` and `rebuild --force`
    keep their old outputs until the new ones are complete. Now the earlier recordings are set aside and
    given back (the new file, of no session, removed); once the new session starts they go."""
    import os
    import signal
    import subprocess
    import sys

    old = earlier_recording(tmp_path / "dup.mcap")
    numbered = earlier_recording(tmp_path / "dup.2.mcap")
    before = {p.name: p.read_bytes() for p in (old, numbered)}
    p = subprocess.Popen([sys.executable, "-m", "pairplay", "session", "--participant", "sim:ashley", "--session",
                          "dup", "--out", str(tmp_path), "--force", "--external", "learner"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         env=dict(os.environ, PYTHONUNBUFFERED="1"))
    try:
        first = p.stdout.readline()
        assert first.startswith("session dup: bus listening on"), first
        p.send_signal(signal.SIGINT)  # the game still waits for its learner
        out, err = p.communicate(timeout=60)
    finally:
        p.kill()
    assert p.returncode == 130, err
    assert err.strip() == (f"pairplay session: interrupted (Ctrl-C) before the session started; {tmp_path / 'dup.mcap'}: "
                           "the earlier recordings are kept (--force replaces them once a new session starts)"), err
    assert {p.name: p.read_bytes() for p in recordings_of(tmp_path / "dup.mcap")} == before  # before: none left
    assert sorted(f.name for f in tmp_path.iterdir()) == ["dup.2.mcap", "dup.mcap"]

    # a session that starts replaces them, once its recording is finished
    assert main(["session", "--participant", "sim:ashley", "--session", "dup", "--rounds", "1", "--out", str(tmp_path),
                 "--force", "-q"]) == 0
    assert [f.name for f in tmp_path.iterdir()] == ["dup.mcap"]
    assert read_log(tmp_path / "dup.mcap").of("SessionEnded")[0].reason == "completed"
