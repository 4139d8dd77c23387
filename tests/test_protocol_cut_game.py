"""A study game cut by a second Ctrl-C (or a crash) is journaled, said, and never played or counted twice.

A new user's trial: `protocol pilot` got a second Ctrl-C as its game's recorder finished; the game had completed
(its recording holds SessionEnded completed) but the file was left without its end, its recorder's journal beside
it, and the study journal with its GameStarted and no GameEnded. Every verb then showed it "running": `protocol
status` "[open]" with no word of it, `report` "left out: ... (running)", and the next `pilot` played its step again,
silently; once the cut game was completed by hand, both counted (13 valid games of a 12-game plan). Now the next
serve, pilot or report (and export, mark-invalid) journals it from what its recording and the journal beside it
hold, completed or aborted (its step played again), in one line; status says so on the step's line; a game of a
step played again is counted once (replay/studydata.py `_counted_once`). Real processes and signals: the second
Ctrl-C lands while the recorder is held before its file's end (pairplay/testpause.py: the first at
`recorder-closing`, the second at `recorder-ending`).
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import zipfile

import msgspec

from pairplay.replay.studydata import StudyData
from pairplay.replay.wal import JournalWriter, read_journal, wal_path
from pairplay.schemas import journal as j
from pairplay.services.bus import Bus, BusOptions
from pairplay.services.protocol import StudyRunner
from pairplay.services.scripted import ScriptedPlayer

from test_protocol_interrupted import STUDY, api, study_with

LIMIT_S = 300


def pilot_paused(tmp_path, moments: tuple[str, ...]) -> tuple[StudyData, str, subprocess.Popen]:
    """A study of 2 and its `protocol pilot` process, to pause at each of `moments` (pairplay/testpause.py): (its
    folder, its first game's session, the process)."""
    data = study_with(tmp_path, STUDY.read_text(), participants=2)
    session = data.session_id(next(iter(data.state.participants)), "phase1", 0)
    proc = subprocess.Popen([sys.executable, "-m", "pairplay", "protocol", "pilot", str(data.folder), "--personas",
                             "tatiana,blind"], cwd=tmp_path, text=True, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE,
                            env=dict(os.environ, PYTHONUNBUFFERED="1", PAIRPLAY_TEST_PAUSE=";".join(
                                f"{m}:{tmp_path / f'go-{m}'}" for m in moments)))
    return data, session, proc


def paused_at(err, moment: str) -> None:
    """The process's next test pause (its stderr's lines `err`) is at `moment`."""
    assert next(line for line in err if line.startswith("pairplay-test:")) == f"pairplay-test: paused at {moment}\n"


def cut_by_a_second_ctrl_c(tmp_path, first_signal_late: bool = False) -> tuple[StudyData, str]:
    """A study of 2 whose `protocol pilot` got two Ctrl-C as its first game's recorder finished: (its folder read,
    the game's session). `first_signal_late`: the thread the first signal's handler starts (services/bus.py
    stop_on_signals: it sets the stop flag and stops the game) is held until the process has ended, as a loaded
    machine may run it late."""
    moments = ("recorder-closing", "recorder-ending")
    data, session, proc = pilot_paused(tmp_path, moments + ("signal-stopping",) * first_signal_late)
    err = iter(proc.stderr)
    for moment in moments:  # the first as the game's recorder starts to finish, the second before the file's end
        paused_at(err, moment)
        proc.send_signal(signal.SIGINT)
        if first_signal_late and moment == moments[0]:
            paused_at(err, "signal-stopping")  # (held for good: its go-file is never made)
        (tmp_path / f"go-{moment}").touch()
    said = [line.rstrip("\n") for line in err]
    assert proc.wait(LIMIT_S) == 130, said
    recording = data.folder / "recordings" / f"{session}.mcap"
    assert said[-1].startswith(f"pairplay protocol pilot: interrupted again (Ctrl-C) while stopping; {recording} "), \
        said
    assert said[-1].endswith(f"; game {session}: the journal holds its start and no end: the next serve, pilot or "
                             f"report journals it from its recording (`pairplay protocol status {data.folder}` says "
                             "how)"), said
    assert wal_path(recording).exists()
    data = StudyData(data.folder)
    assert data.state.games[session].ended is None
    return data, session


def test_the_cut_line_is_decided_by_the_first_signals_handler_not_by_its_thread(tmp_path):
    """Once at load 5.4 the second Ctrl-C's line was cli/main.py's "interrupted (Ctrl-C); nothing more was written":
    the thread the first signal's handler starts sets the stop flag and names the stopped game, and pilot's cut path
    read both; that thread had not run yet. Here it is held until the process has ended: the line is the cut game's
    (the assertions of `cut_by_a_second_ctrl_c`), decided from what the handler itself noted."""
    data, session = cut_by_a_second_ctrl_c(tmp_path, first_signal_late=True)
    assert data.state.games[session].ended is None


def test_a_first_signal_whose_thread_runs_late_still_ends_the_plan_after_its_game(tmp_path):
    """The same late thread, one signal: the plan stops after the game the signal came in and pilot says so. Before,
    the next step was decided from a flag that thread sets: the plan went on and its next game started."""
    data, session, proc = pilot_paused(tmp_path, ("recorder-closing", "signal-stopping"))
    err = iter(proc.stderr)
    paused_at(err, "recorder-closing")
    proc.send_signal(signal.SIGINT)
    paused_at(err, "signal-stopping")  # (held for good: its go-file is never made)
    (tmp_path / "go-recorder-closing").touch()
    said = [line.rstrip("\n") for line in err]
    assert proc.wait(LIMIT_S) == 130, said
    assert said[-1].startswith(f"pairplay protocol pilot: interrupted (Ctrl-C); game {session} had completed all 2 "
                               "rounds, journaled completed; "), said
    after = StudyData(data.folder)
    assert list(after.state.games) == [session], after.state.games  # no game after it
    assert after.state.games[session].ended.outcome == "completed"


def test_a_game_cut_after_its_end_is_said_by_status_and_journaled_completed_by_the_next_verb(tmp_path, pairplay_cli):
    data, session = cut_by_a_second_ctrl_c(tmp_path)
    folder = data.folder
    recording = folder / "recordings" / f"{session}.mcap"
    status = pairplay_cli("protocol", "status", folder)
    assert status.returncode == 0, status
    [line] = [line for line in status.stdout.splitlines() if "p01: phase1 game 1" in line]
    assert line.startswith("[open   ] p01: phase1 game 1  (" f"{session}: its end is not journaled; the next serve, "
                           f"pilot or report journals it completed from its cut recording recordings/{session}.mcap: "
                           "it was cut after the game's end (its SessionEnded is in "), line
    assert StudyData(folder).state.games[session].ended is None  # status writes nothing
    ran = pairplay_cli("report", folder)
    assert ran.returncode == 0, ran
    assert (f"pairplay report: {session}: journaled completed from its cut recording recordings/{session}.mcap: it "
            "was cut after the game's end (its SessionEnded is in ") in ran.stderr, ran.stderr
    assert f"its policy: `pairplay recover {recording}` writes its recovered copy" in ran.stderr, ran.stderr
    assert "(running)" not in (folder / "report" / "report.md").read_text()
    after = StudyData(folder)
    ended = after.state.games[session].ended
    assert (ended.outcome, ended.rounds_played, ended.questionnaire) == ("completed", 2, True), ended
    assert after.next_step().label == "p01: phase1 game 2"  # its step is done: not played again
    assert "[done   ] p01 (scripted: tatiana): phase1 game 1" in pairplay_cli("protocol", "status", folder).stdout
    # recovered, its policy is built from the copy, as for any completed game journaled without one
    assert pairplay_cli("recover", recording).returncode == 0
    ran = pairplay_cli("report", folder, "--force")
    assert f"pairplay report: {session}: policy built from its recovered copy recordings/{session}.recovered.mcap: " \
           in ran.stderr, ran.stderr
    assert (folder / StudyData(folder).state.games[session].ended.policy).is_file()


def test_a_game_cut_before_its_end_is_journaled_aborted_and_its_step_played_again(tmp_path, pairplay_cli):
    data, session = cut_by_a_second_ctrl_c(tmp_path)
    folder = data.folder
    recording = folder / "recordings" / f"{session}.mcap"
    # a crash before the game's end: the file and the journal beside it hold its first round and no more
    records = read_journal(wal_path(recording)).records  # (every event its recorder received)
    first = records[:next(i for i, (key, _, _) in enumerate(records) if key.endswith("/RoundEnded")) + 1]
    recording.write_bytes(recording.read_bytes()[:1024])  # its header and little else
    wal_path(recording).unlink()
    journal = JournalWriter(recording, session)
    for key, payload, _ in first:
        journal.add((key, payload))
    journal.close()
    status = pairplay_cli("protocol", "status", folder)
    assert (f"[open   ] p01: phase1 game 1  ({session}: its end is not journaled; the next serve, pilot or report "
            f"journals it aborted (its recording was cut before the game's end: its cut recording "
            f"recordings/{session}.mcap, after 0 whole rounds); its step is played again)") \
        in status.stdout.splitlines(), status.stdout
    ran = pairplay_cli("report", folder)
    assert (f"pairplay report: {session}: journaled aborted (its recording was cut before the game's end: its cut "
            f"recording recordings/{session}.mcap, after 0 whole rounds); its step is played again") \
        in ran.stderr.splitlines(), ran.stderr
    after = StudyData(folder)
    assert after.state.games[session].ended.outcome == "aborted"
    assert after.next_step().label == "p01: phase1 game 1"  # played again, as the line says


def test_a_step_played_again_before_its_cut_games_end_was_journaled_counts_once(tmp_path, pairplay_cli):
    """What main did: the next pilot played the cut game's step again (`-r1`), both then counted. The game journaled
    completed first counts (it may be combined and reported already); the other is journaled and marked invalid."""
    data, session = cut_by_a_second_ctrl_c(tmp_path)
    pid = data.state.games[session].participant
    with Bus(BusOptions()) as bus:  # played again, as main's next pilot did (its step was open)
        runner = StudyRunner(data, bus)
        name, items = runner.questions_for(pid, "phase1")
        replay = runner.run_game(pid, "phase1", 0, ScriptedPlayer("tatiana", questions=items, questionnaire=name))
    assert replay.session == f"{session}-r1" and replay.valid_complete
    ran = pairplay_cli("report", data.folder)
    assert ran.returncode == 0, ran
    assert (f"pairplay report: {session}: marked invalid: its step was played again as {session}-r1 before its end "
            f"was journaled; {session}-r1 counts") in ran.stderr.splitlines(), ran.stderr
    after = StudyData(data.folder)
    assert after.state.games[session].ended.outcome == "completed"
    assert [g.session for g in after.state.games.values() if g.valid_complete] == [f"{session}-r1"]
    assert "1 valid game of 1 participant" in ran.stdout + ran.stderr, ran
    assert [e for e in after.read_journal() if isinstance(e, j.SessionMarkedInvalid)][0].session == session


def test_the_next_serve_journals_the_cut_game_says_so_and_its_console_lists_it_completed(tmp_path):
    """The restarted console listed the cut game as 'running', and offered its step again."""
    data, session = cut_by_a_second_ctrl_c(tmp_path)
    proc = subprocess.Popen([sys.executable, "-m", "pairplay", "protocol", "serve", str(data.folder)], cwd=tmp_path,
                            text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            env=dict(os.environ, PYTHONUNBUFFERED="1"))
    try:
        console = next(line for line in proc.stdout if "experimenter console:" in line)
        base, token = console.split("experimenter console: ", 1)[1].strip().split("/console?token=")
        state = api(f"{base}/api/console/state", token)
        [game] = [g for g in state["games"] if g["session"] == session]
        assert (game["outcome"], game["rounds"], game["questionnaire"]) == ("completed", 2, True), game
        assert next(s for s in state["plan"] if not s["done"])["label"] == "p01: phase1 game 2", state["plan"]
    finally:
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=LIMIT_S)
    assert any(line.startswith(f"pairplay protocol serve: {session}: journaled completed from its cut recording "
                               f"recordings/{session}.mcap: it was cut after the game's end")
               for line in err.splitlines()), err


def test_an_export_and_a_mark_invalid_journal_the_cut_game_first(tmp_path, pairplay_cli):
    """The participant's export said the cut game was "running" (its README); mark-invalid marked a game with no end."""
    data, session = cut_by_a_second_ctrl_c(tmp_path)
    other = shutil.copytree(data.folder, tmp_path / "copy")  # the same cut game, for the second verb
    folder = data.folder
    ran = pairplay_cli("participant", "export", folder, "p01")
    assert ran.returncode == 0, ran
    assert ran.stderr.startswith(f"pairplay participant export: {session}: journaled completed from its cut "
                                 f"recording recordings/{session}.mcap: "), ran.stderr
    with zipfile.ZipFile(folder / "exports" / "p01.zip") as z:
        readme = z.read("README.txt").decode()
    assert "running" not in readme, readme
    assert StudyData(folder).state.games[session].ended.outcome == "completed"
    ran = pairplay_cli("protocol", "mark-invalid", other, session, "--reason", "a rehearsal")
    assert ran.returncode == 0, ran
    assert ran.stderr.startswith(f"pairplay protocol mark-invalid: {session}: journaled completed from its cut "
                                 f"recording recordings/{session}.mcap: "), ran.stderr
    game = StudyData(other).state.games[session]
    assert (game.ended.outcome, game.invalid) == ("completed", "a rehearsal"), game


def test_a_cut_game_whose_end_says_interrupted_is_journaled_aborted_as_it_says_and_played_again(tmp_path,
                                                                                                pairplay_cli):
    from pairplay.schemas.events import decode_event, encode_event

    data, session = cut_by_a_second_ctrl_c(tmp_path)
    recording = data.folder / "recordings" / f"{session}.mcap"
    records = read_journal(wal_path(recording)).records
    recording.write_bytes(recording.read_bytes()[:1024])  # the end in the journal alone
    wal_path(recording).unlink()
    journal = JournalWriter(recording, session)
    for key, payload, _ in records:
        if key.endswith("/SessionEnded"):  # a game a signal stopped before its last round
            payload = encode_event(msgspec.structs.replace(decode_event(payload), reason="interrupted",
                                                           detail="SIGINT"))
        journal.add((key, payload))
    journal.close()
    ran = pairplay_cli("report", data.folder)
    assert (f"pairplay report: {session}: journaled aborted from its cut recording recordings/{session}.mcap: it was "
            "cut after the game's end (its SessionEnded is in its recorder's journal beside it); its step is played "
            "again") in ran.stderr.splitlines(), ran.stderr
    after = StudyData(data.folder)
    assert (after.state.games[session].ended.outcome, after.state.games[session].ended.reason) == \
        ("aborted", "interrupted: SIGINT")
    assert after.next_step().label == "p01: phase1 game 1"
