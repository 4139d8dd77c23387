"""A completed game whose questionnaire is cut by a signal stays completed, and its policy is built later.

`pairplay protocol serve` is a real process: the console's API starts a game whose participant
plays on the board page (its WebSocket, driven by the test as a person's page would be), the game
completes, the server waits for the questionnaire the participant has not answered, and the process
gets SIGTERM. Before: the journal said the game was aborted ("interrupted (SIGTERM)",
no policy): open to be replayed and left out of the combination, though its recording held the
whole game. Now it is journaled completed (questionnaire unanswered) and the next verb that runs or
reports the study builds its policy from the recording (PolicyBuilt in the journal). A recording
that cannot give it is said in one line and the game left as it is; the combination refuses to go
without a valid game's policy.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
import urllib.request
from pathlib import Path

import pytest

from pairplay.replay.mcapscan import scan

from pairplay.replay.studydata import StudyData, StudyDataError
from pairplay.replay.wal import wal_path
from pairplay.schemas import journal as j
from pairplay.services.bus import SHUTDOWN_S, Bus, BusOptions
from pairplay.services.protocol import StudyRunner
from pairplay.services.scripted import ScriptedPlayer

STUDY = Path(__file__).parent / "data" / "pilot-study.toml"
# phase 1's questionnaire asks a new participant nothing (all its items are for returning ones)
UNASKED = STUDY.read_text().replace(
    'players = "new"\nquestionnaires = ["after-game"]', 'players = "new"\nquestionnaires = ["later"]') + '''
[questionnaire.later]
title = "Asked of returning participants only"

[[questionnaire.later.item]]
id = "again"
text = "Was this game different from your first ones?"
kind = "text"
required = false
ask = "returning"
'''


def study_with(tmp_path: Path, text: str, participants: int = 1) -> StudyData:
    toml = tmp_path / "study.toml"
    toml.write_text(text)
    data = StudyData.create(tmp_path / "study", toml)
    for _ in range(participants):
        data.register("phase1", consent=True)
    return data


def api(url: str, token: str, body: dict | None = None) -> dict:
    request = urllib.request.Request(url, data=None if body is None else json.dumps(body).encode(),
                                     headers={"x-pairplay-token": token, "content-type": "application/json"})
    with urllib.request.urlopen(request, timeout=30) as answer:
        return json.loads(answer.read())


def serve_until_questionnaire(folder: Path) -> tuple[subprocess.Popen, str]:
    """A `protocol serve` process whose console started the next game, played on its board page, once the
    game is over and the server waits for the questionnaire nobody answers; (process, session)."""
    proc = subprocess.Popen([sys.executable, "-m", "pairplay", "protocol", "serve", str(folder)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ, PYTHONUNBUFFERED="1"))
    err: list[str] = []
    threading.Thread(target=lambda: err.extend(proc.stderr), daemon=True).start()
    try:
        line = ""
        while "experimenter console:" not in line:
            line = proc.stdout.readline()
            assert line, f"serve ended before its console: {''.join(err)}"
        console = line.split("experimenter console: ", 1)[1].strip()
        base, token = console.split("/console?token=")
        api(f"{base}/api/console/next", token, {})
        deadline = time.monotonic() + 60
        while "board_url" not in (live := api(f"{base}/api/console/state", token)["live"]):
            assert time.monotonic() < deadline, live
            time.sleep(0.1)
        play_the_board(base.replace("http", "ws", 1) + live["board_url"].replace("/board?", "/ws?") +
                       "&page=board&client=person")
        deadline = time.monotonic() + 60
        while (state := api(f"{base}/api/console/state", token))["live"]["state"] != "questionnaire":
            assert time.monotonic() < deadline, state
            time.sleep(0.1)
        assert "questionnaire_url" in state["live"], state  # a real questionnaire awaits its answers
        proc.stderr_lines = err
        return proc, state["live"]["session"]
    except BaseException:
        proc.kill()
        proc.wait()
        raise


def play_the_board(url: str, timeout_s: float = 120.0) -> None:
    """Play a game on the board page's WebSocket as a person with a perfect memory would (services/lab/hub.py
    says what goes over it): a pair whose faces were seen, else a card not seen yet; until the game is over."""
    from websockets.sync.client import connect

    known: dict[int, int] = {}  # card -> face, of the cards of this round's deal seen and not matched
    acted, sent, deal = None, 0, None
    deadline = time.monotonic() + timeout_s
    with connect(url, open_timeout=30) as ws:
        view = None
        while True:
            message = json.loads(ws.recv(timeout=max(0.1, deadline - time.monotonic())))
            if message["type"] == "rejected":
                acted = None  # a pick that came too early or late: choose again
            elif message["type"] == "state":
                view = message["state"]
            if view is None:
                continue
            if view["phase"] == "over":
                return
            if view["round"] != deal:  # a new round, a new deal
                known, deal = {}, view["round"]
            cards = view["cards"]
            for card, c in enumerate(cards):
                if c["state"] == "matched":
                    known.pop(card, None)
                elif c["face"] >= 0:
                    known[card] = c["face"]
            turn = view["last_turn"]
            if turn and not turn["matched"] and turn["round"] == deal:
                known.update(zip(turn["cards"], turn["faces"]))
            down = [card for card, c in enumerate(cards) if c["state"] == "down"]
            if not down:  # the round is over: the next one's deal comes
                continue
            here = (view["round"], view["turn"])
            if view["phase"] == "first" and acted != (*here, 0):
                pair = next((a for a in down for b in down if a != b and known.get(a, -1) == known.get(b, -2)), None)
                card = pair if pair is not None else next((c for c in down if c not in known), down[0])
                acted = (*here, 0)
            elif view["phase"] == "second" and acted == (*here, 0):
                face = known.get(view["first"], cards[view["first"]]["face"])
                card = next((c for c in down if known.get(c) == face), None)
                if card is None:
                    card = next((c for c in down if c not in known), down[0])
                acted = (*here, 1)
            else:
                continue
            sent += 1
            ws.send(json.dumps({"type": "pick", "id": sent, "round": here[0], "turn": here[1], "card": card,
                                "page_ms": time.time() * 1000}))


def test_a_signal_during_the_questionnaire_keeps_the_completed_game_and_its_policy_is_built_next(
        tmp_path, pairplay_cli):
    data = study_with(tmp_path, STUDY.read_text())
    proc, session = serve_until_questionnaire(data.folder)
    time.sleep(0.3)  # the server is waiting for the answers
    proc.send_signal(signal.SIGTERM)
    # a starved process (load ~15 failed so): frozen right after the signal until its shutdown's deadline has
    # passed, so every wait on others has no time left; the game's end is its own fact and is journaled anyway
    time.sleep(0.05)
    proc.send_signal(signal.SIGSTOP)
    time.sleep(SHUTDOWN_S + 0.4)
    proc.send_signal(signal.SIGCONT)
    try:
        proc.wait(timeout=30)
    finally:
        proc.kill()
    assert "stopped (SIGTERM)" in "".join(proc.stderr_lines)

    game = StudyData(data.folder).state.games[session]
    # before: outcome "aborted", reason "interrupted (SIGTERM)": the complete game was to be played again
    assert (game.ended.outcome, game.ended.reason, game.ended.rounds_played) == ("completed", "", 2), game.ended
    assert game.valid_complete and not game.ended.questionnaire and game.ended.policy == ""
    assert StudyData(data.folder).next_step().game == 1  # game 1 of p01 is done, not to be replayed

    # the next verb that reports (or serves, pilots) the study builds the policy from the recording
    done = pairplay_cli("report", data.folder)
    assert done.returncode == 0, done.stderr
    assert f"pairplay report: {session}: policy built from its recording: policies/{session}.policy.json" \
        in done.stderr.splitlines(), done.stderr
    again = StudyData(data.folder)
    assert again.state.games[session].ended.policy == f"policies/{session}.policy.json"
    assert (data.folder / again.state.games[session].ended.policy).is_file()
    assert [type(e).__name__ for e in again.read_journal()][-1] == "PolicyBuilt"
    assert f"policies/{session}.policy.json" in (data.folder / "sessions.csv").read_text()
    # said once: a second report builds nothing
    done = pairplay_cli("report", data.folder, "--force")
    assert done.returncode == 0 and "policy built" not in done.stderr, done.stderr


def test_a_questionnaire_that_asks_this_participant_nothing_does_not_hold_the_game(tmp_path):
    """Before: a phase naming a questionnaire held every game for its answers, though all its items were
    for returning participants: a new one was asked nothing and the session waited (the console showed an
    empty questionnaire) until the experimenter skipped it or the timeout. Now what the participant is
    asked (StudyRunner.questions_for) decides: no item, no questionnaire link, no wait."""
    data = study_with(tmp_path, UNASKED)
    pid = next(iter(data.state.participants))
    ended: list[float] = []
    tokens: list[str] = []
    with Bus(BusOptions()) as bus:
        runner = StudyRunner(data, bus, questionnaire_timeout_s=45.0)
        name, items = runner.questions_for(pid, "phase1")
        assert (name, items) == ("later", [])

        def seen(e) -> None:
            if type(e).__name__ == "SessionEnded":
                ended.append(time.monotonic())
                tokens.append(runner.live.questionnaire_token)
        game = runner.run_game(pid, "phase1", 0, ScriptedPlayer("ashley", questions=items, questionnaire=name),
                               on_event=seen)
        returned = time.monotonic()
    assert game.ended.outcome == "completed" and not game.ended.questionnaire and game.ended.policy
    assert tokens == [""]  # the console offers no questionnaire link
    assert returned - ended[0] < 20, returned - ended[0]  # before: the 45 s timeout, waiting for no answer


def completed_without_policy(tmp_path: Path, stripped: int = 4) -> StudyData:
    """A study of 2 participants whose phase-1 games completed in-process (answers given), the first
    `stripped` of them then journaled as a signal during the questionnaire leaves them: completed, no
    policy (the policy files removed)."""
    data = study_with(tmp_path, STUDY.read_text(), 2)
    with Bus(BusOptions()) as bus:
        runner = StudyRunner(data, bus)
        for pid in list(data.state.participants):
            for g in range(2):
                name, items = runner.questions_for(pid, "phase1")
                runner.run_game(pid, "phase1", g, ScriptedPlayer("ashley", questions=items, questionnaire=name))
    lines = []
    for e in data.read_journal():
        if isinstance(e, j.GameEnded) and stripped > 0:
            stripped -= 1
            (data.folder / e.policy).unlink()
            e = j.GameEnded(session=e.session, participant=e.participant, outcome="completed",
                            rounds_played=e.rounds_played, questionnaire=True, time_ns=e.time_ns)
        lines.append(j.encode_line(e))
    (data.folder / "journal.jsonl").write_bytes(b"".join(lines))
    return StudyData(data.folder)


def test_a_recording_that_cannot_give_the_policy_is_said_in_one_line_and_the_combination_refuses(tmp_path):
    data = completed_without_policy(tmp_path)
    games = list(data.state.games.values())
    assert all(g.valid_complete and not g.ended.policy for g in games)  # an older journal reads as it did
    unfinished, missing, cut = games[0], games[1], games[2]
    shutil.copy(data.folder / unfinished.recording, wal_path(data.folder / unfinished.recording))  # a killed recorder's
    (data.folder / missing.recording).unlink()
    whole = (data.folder / cut.recording).read_bytes()
    # cut after its last chunk, before its Data End: what came after is unknown (more chunks?), so cut short;
    # half the file fell in its summary, after every message and the Data End: that cut lost nothing
    last = scan(data.folder / cut.recording).chunks[-1]
    (data.folder / cut.recording).write_bytes(whole[: last.offset + last.length + 5])
    lines = data.build_missing_policies()
    assert len(lines) == 4 and all("\n" not in line for line in lines), lines
    said = {line.split(":", 1)[0]: line for line in lines}
    assert "was not finished" in said[unfinished.session] and "pairplay recover" in said[unfinished.session]
    assert "is missing" in said[missing.session]
    assert "is partial: truncated" in said[cut.session]
    assert "policy built from its recording" in said[games[3].session]
    for g in games[:3]:
        assert g.valid_complete and g.ended.policy == ""  # left as it is
    assert games[3].ended.policy
    # the combination never goes without a valid game's policy, silently: it says which and why
    with Bus(BusOptions()) as bus:
        with pytest.raises(StudyDataError, match=f"combining for phase2: {unfinished.session}: completed, but no "
                                                 "policy built: .*mark the game invalid"):
            StudyRunner(data, bus).combine("phase2")
    # the one built is journaled once: read again, nothing more to build for it
    assert [line for line in StudyData(data.folder).build_missing_policies() if "policy built from" in line] == []


def test_a_policy_file_deleted_by_hand_is_built_again_and_said(tmp_path):
    """A completed game's policy file deleted by hand (the journal still names it) was neither rebuilt nor
    reported by serve, pilot or report: build_missing_policies skipped every game journaled with a policy.
    Now it is built again from the recording (the event log is the truth), journaled and said."""
    data = completed_without_policy(tmp_path, stripped=0)
    game = next(iter(data.state.games.values()))
    policy = data.folder / game.ended.policy
    before = policy.read_bytes()
    policy.unlink()
    lines = StudyData(data.folder).build_missing_policies()
    assert lines == [f"{game.session}: its policy {game.ended.policy} is missing; policy built from its recording: "
                     f"{game.ended.policy}"], lines
    assert policy.read_bytes() == before
    assert StudyData(data.folder).build_missing_policies() == []  # said once
    policy.unlink()
    (data.folder / game.recording).unlink()  # nothing to build it from: said, left as it is
    [line] = StudyData(data.folder).build_missing_policies()
    assert line.startswith(f"{game.session}: completed, but its policy {game.ended.policy} is missing; no policy "
                           "built: its recording"), line


def test_the_combination_builds_a_missing_policy_it_needs_and_combines(tmp_path):
    """Before: a valid game without its policy was left out of the combination without a word."""
    data = completed_without_policy(tmp_path, stripped=1)
    with Bus(BusOptions()) as bus:
        combined = StudyRunner(data, bus).combine("phase2")
    assert sorted(combined.inputs) == sorted(f"policies/{g.session}.policy.json" for g in data.state.games.values())
    assert sum(isinstance(e, j.PolicyBuilt) for e in data.read_journal()) == 1


class Silent(ScriptedPlayer):
    """Plays the whole game and never answers the questionnaire."""


def test_an_abort_during_the_questionnaire_keeps_the_completed_game_with_its_policy(tmp_path):
    """The console's abort (or skip) while the questionnaire is awaited: the game is over, so it stays
    completed, its policy built as always (services/protocol.py abort, _finish)."""
    data = study_with(tmp_path, STUDY.read_text())
    with Bus(BusOptions()) as bus:
        runner = StudyRunner(data, bus)

        def watch(e):
            if type(e).__name__ == "SessionEnded":
                def abort():
                    while runner.live.state != "questionnaire":
                        time.sleep(0.01)
                    runner.abort("the participant had to leave")
                threading.Thread(target=abort).start()
        game = runner.run_game("p01", "phase1", 0, Silent("ashley"), on_event=watch)
    assert (game.ended.outcome, game.ended.reason, game.ended.questionnaire) == ("completed", "", False)
    assert game.ended.policy and (data.folder / game.ended.policy).is_file()


def test_a_game_whose_end_was_never_journaled_is_journaled_from_its_finished_recording(tmp_path):
    """The process went while it read a finished game back (a signal then, the console's step cut at the
    exit): its GameStarted has no GameEnded. Before: it stayed "running" for ever, its step open to be
    played again. Now its end, policy and questionnaire come from the recording; a game whose recording
    is not finished (a recorder's journal beside it, no live recorder: one killed) is journaled from what it holds,
    its policy once recovered (tests/test_protocol_cut_game.py)."""
    data = completed_without_policy(tmp_path, stripped=0)
    games = list(data.state.games.values())
    ends = {e.session: e for e in data.read_journal() if isinstance(e, j.GameEnded)}
    cut, running = games[0], games[1]
    for g in (cut, running):
        (data.folder / ends[g.session].policy).unlink()
    shutil.copy(data.folder / running.recording, wal_path(data.folder / running.recording))
    kept = [j.encode_line(e) for e in data.read_journal()
            if not (isinstance(e, j.GameEnded) and e.session in (cut.session, running.session))]
    (data.folder / "journal.jsonl").write_bytes(b"".join(kept))
    data = StudyData(data.folder)
    assert data.state.games[cut.session].ended is None and not data.state.games[cut.session].valid_complete

    assert data.build_missing_policies() == [
        f"{cut.session}: journaled completed from its recording (the server stopped before it said how the game ended)",
        f"{running.session}: journaled completed from its cut recording {running.recording}: it was cut after the "
        f"game's end (its SessionEnded is in the file); its policy: `pairplay recover {data.folder / running.recording}` "
        "writes its recovered copy, which the next serve, pilot or report builds it from"]
    ended = StudyData(data.folder).state.games[cut.session].ended
    assert ended == j.GameEnded(session=cut.session, participant=cut.participant, outcome="completed", rounds_played=2,
                                policy=ends[cut.session].policy, questionnaire=True, time_ns=ended.time_ns)
    assert (data.folder / ended.policy).is_file()
    assert data.state.games[running.session].ended.policy == ""  # not finished: its policy once recovered


def test_a_combination_of_a_partial_policy_journals_its_profiles_as_partial(tmp_path):
    """The combiner's merged file of a partial input policy says so (core/policies.py partial_inputs) and
    `pairplay profile` says "PARTIAL profile: ..."; the protocol's combine step journaled the users' profiles
    (BiasCombined, shown by the console and the report) with no word of it. Now the event carries the
    merged file's very reason, and it reads back from the journal."""
    import msgspec

    from pairplay.schemas import policy as policy_file

    data = completed_without_policy(tmp_path, stripped=0)
    game = next(iter(data.state.games.values()))
    why = "lost 2 messages that do not decode"
    path = data.folder / game.ended.policy
    policy_file.write_policy(path, msgspec.structs.replace(policy_file.read_policy(path), partial=why), force=True)
    with Bus(BusOptions()) as bus:
        event = StudyRunner(data, bus).combine("phase2")
    expected = f"made of a partial policy: {game.ended.policy} ({why})"
    assert event.partial == expected, event.partial
    assert policy_file.read_policy(data.folder / event.output).partial == expected  # the combiner's, the same
    assert StudyData(data.folder).state.combined["phase2"].partial == expected


def test_a_game_journaled_from_a_recording_whose_answers_do_not_decode_is_answered_and_gets_no_policy(tmp_path):
    """The end of a game never journaled, taken from its finished recording (build_missing_policies, game_end):
    a QuestionnaireAnswered that does not decode made it journaled unanswered (the participant had answered;
    answers.csv says the answers were lost), and its policy was built from a recording that lost an event, no
    word. Now it is answered, gets no policy, and its reason says why in the reader's words."""
    from damageutil import damage

    data = completed_without_policy(tmp_path, stripped=0)
    cut = next(iter(data.state.games.values()))
    (data.folder / cut.ended.policy).unlink()
    kept = [j.encode_line(e) for e in data.read_journal()
            if not (isinstance(e, j.GameEnded) and e.session == cut.session)]
    (data.folder / "journal.jsonl").write_bytes(b"".join(kept))
    damage(data.folder / cut.recording, "undecodable", tag="QuestionnaireAnswered")
    data = StudyData(data.folder)
    [line] = data.build_missing_policies()
    assert line.startswith(f"{cut.session}: journaled completed from its recording"), line
    ended = StudyData(data.folder).state.games[cut.session].ended
    assert ended.questionnaire and ended.policy == "", ended
    assert ended.reason.startswith("recording damaged: 1 message in it does not decode (") \
        and ended.reason.endswith(": no policy built"), ended.reason
    assert not list((data.folder / "policies").glob(f"{cut.session}*"))


# -- a file of the folder and its journal line: the file first, no file without its line (journaled_or_removed) --

def _hand_edit_once(path: Path, journal: Path, go: Path) -> threading.Thread:
    """Once `path` is written (a glob pattern in its last part), the journal is changed as another process
    would (its time), then the held verb goes on (pairplay/testpause.py): the line it then writes is refused
    (a stale copy)."""
    def edit():
        while not list(path.parent.glob(path.name)):
            time.sleep(0.01)
        st = journal.stat()
        os.utime(journal, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000))
        go.touch()
    thread = threading.Thread(target=edit, daemon=True)
    thread.start()
    return thread


def test_a_combination_whose_line_is_refused_leaves_no_bias_policy(tmp_path, monkeypatch):
    """Before: the combiner's file stayed in merged/ with no BiasCombined (a participant's deletion, which reads
    the journal, would not know it)."""
    data = completed_without_policy(tmp_path, stripped=0)
    output = data.folder / "merged" / "phase2-bias.policy.json"
    go = tmp_path / "go"
    monkeypatch.setenv("PAIRPLAY_TEST_PAUSE", f"bias-written:{go}")
    # the combiner writes it under a hidden name, put in place with the line (services/biasfile.py)
    editor = _hand_edit_once(output.with_name(".phase2-bias.policy.json.*.combining"), data.folder / "journal.jsonl",
                             go)
    with Bus(BusOptions()) as bus:
        with pytest.raises(StudyDataError, match="changed by another process"):
            StudyRunner(data, bus).combine("phase2")
    editor.join(10)
    assert not output.exists() and list((data.folder / "merged").iterdir()) == []
    assert not any(isinstance(e, j.BiasCombined) for e in StudyData(tmp_path / "study").read_journal())


def test_a_built_policy_whose_line_is_refused_is_removed(tmp_path, monkeypatch):
    """Before: build_missing_policies' file stayed in policies/ with no PolicyBuilt."""
    data = completed_without_policy(tmp_path, stripped=1)
    game = next(g for g in data.state.games.values() if not g.ended.policy)
    policy = data.folder / "policies" / f"{game.session}.policy.json"
    go = tmp_path / "go"
    monkeypatch.setenv("PAIRPLAY_TEST_PAUSE", f"policy-written:{go}")
    editor = _hand_edit_once(policy, data.folder / "journal.jsonl", go)
    with pytest.raises(StudyDataError, match="changed by another process"):
        data.build_missing_policies()
    editor.join(10)
    assert not policy.exists()


def test_a_deletion_erases_a_policy_a_killed_build_left_without_its_line(tmp_path):
    """A build killed between a game's policy and its PolicyBuilt left the file unnamed by the journal; before,
    deleting the participant left it (files_of read only the journal's names)."""
    from pairplay.replay.rebuild import rebuild_recording
    from pairplay.replay.studydata import write_game_policy

    data = completed_without_policy(tmp_path, stripped=1)
    game = next(g for g in data.state.games.values() if not g.ended.policy)
    left = data.folder / write_game_policy(data.folder, rebuild_recording(data.folder / game.recording), force=True)
    assert left.is_file()
    StudyData(data.folder).delete_participant(game.participant)
    assert not left.exists()


def test_a_build_keeps_a_file_of_the_researcher_beside_the_game_s_policy(tmp_path):
    """The build wrote policies/<session>.curve.csv with force and then removed it: a researcher's file of that
    name (`pairplay rebuild` writes one) was replaced and deleted without a word. Nor is a file at the policy's
    place replaced unless it is this build's own, to the byte (a build killed before its line left it)."""
    data = completed_without_policy(tmp_path, stripped=2)
    lacking = [g for g in data.state.games.values() if not g.ended.policy]
    curve = data.folder / "policies" / f"{lacking[0].session}.curve.csv"
    curve.write_text("mine\n")
    mine = data.folder / "policies" / f"{lacking[1].session}.policy.json"
    mine.write_text('{"mine": true}\n')
    lines = data.build_missing_policies()
    assert curve.read_text() == "mine\n" and mine.read_text() == '{"mine": true}\n'
    assert lines[0] == f"{lacking[0].session}: policy built from its recording: policies/{lacking[0].session}.policy.json"
    assert lines[1] == (f"{lacking[1].session}: completed, but no policy built: its policy cannot be written: exists, "
                        f"not this game's policy as pairplay builds it: move it away ({mine})"), lines
    state = StudyData(data.folder).state
    assert [bool(state.games[g.session].ended.policy) for g in lacking] == [True, False]


def test_a_build_killed_before_its_line_is_journaled_from_the_file_it_left(tmp_path):
    """The file a build killed before its PolicyBuilt left is this build's to the byte: taken, journaled."""
    data = completed_without_policy(tmp_path, stripped=1)
    [game] = [g for g in data.state.games.values() if not g.ended.policy]
    data.build_missing_policies()
    built = data.folder / "policies" / f"{game.session}.policy.json"
    kept = built.read_bytes()
    journal = data.folder / "journal.jsonl"
    journal.write_bytes(b"".join(j.encode_line(e) for e in data.read_journal() if not isinstance(e, j.PolicyBuilt)))
    [line] = StudyData(data.folder).build_missing_policies()
    assert line.endswith(f"policy built from its recording: policies/{game.session}.policy.json"), line
    assert built.read_bytes() == kept
