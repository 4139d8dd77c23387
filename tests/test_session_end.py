"""Every session end says why and how far it got (issue 10, item 6): completed, interrupted by SIGINT or
SIGTERM, aborted by the experimenter, a service failed; `recover` marks what it completed; `rebuild` flags
policies from partial sessions in the policy file and in its output. Old recordings stay readable."""

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from busutil import collect, wait_until

from pairplay import signals
from pairplay.replay.reader import read_log
from pairplay.replay.rebuild import NoWholeRound, rebuild_recording, write_outputs
from pairplay.replay.recover import recover
from pairplay.schemas import events as ev
from pairplay.schemas.policy import read_policy
from pairplay.schemas.keys import event_key
from pairplay.schemas.session import SessionConfig
from pairplay.services.bus import SHUTDOWN_S, Bus, BusOptions
from pairplay.services.session import run_session
from pairplay.services.verify import verify_recording

SAMPLES = Path(__file__).resolve().parent.parent / "recordings" / "samples"


def ended(path):
    return [r.event for r in read_log(path).events if isinstance(r.event, ev.SessionEnded)]


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_a_signalled_session_records_it_was_interrupted_and_how_far_it_got(tmp_path, sig, pairplay_cli):
    """SIGHUP (the terminal closed, the ssh link dropped) killed a session at once, no line, its recording cut (a
    hostile user's trial, trial28 F8): now the same stop as SIGTERM's."""
    p = subprocess.Popen([sys.executable, "-m", "pairplay", "session", "--participant", "sim:wasim", "--rounds",
                          "5000", "--session", "sig", "--out", str(tmp_path)], stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, text=True, env=dict(os.environ, PYTHONUNBUFFERED="1"))
    watcher = None
    try:
        while "bus listening" not in (line := p.stdout.readline()):  # log lines may come first
            assert p.poll() is None
        # the session's router: wait (as `pairplay view` would) until it has played a round
        watcher = Bus(BusOptions(mode="client", connect=[line.split()[-1]]))
        rounds = collect(watcher, event_key("sig", "game", "RoundEnded"))
        rounds.get(timeout=60)
        p.send_signal(sig)
        # a starved process (load 20-29): frozen right after the signal until its shutdown's deadline has passed,
        # so no wait on its services or its robot has any time left; its own end and its file are still whole
        time.sleep(0.05)
        p.send_signal(signal.SIGSTOP)
        time.sleep(SHUTDOWN_S + 0.4)
        p.send_signal(signal.SIGCONT)
        out, _ = p.communicate(timeout=30)
    finally:
        if p.poll() is None:
            p.kill()
        if watcher is not None:
            watcher.close()
    assert p.returncode == 128 + sig, out
    path = tmp_path / "sig.mcap"
    assert read_log(path).whole, out
    [end] = ended(path)
    assert end.reason == "interrupted" and end.detail == sig.name and 1 <= end.rounds_played < 5000
    assert end.round == end.rounds_played and end.turns_in_round >= 0
    rebuilt = rebuild_recording(path)
    assert rebuilt.partial.startswith(f"interrupted ({sig.name}) after {end.rounds_played} of 5000 rounds")
    r = pairplay_cli("rebuild", path, "--out", tmp_path / "rb", "--no-plot")
    assert "PARTIAL session: interrupted" in r.stderr, r.stderr  # a warning: on stderr (cli/main.py `warn`)
    assert read_policy(tmp_path / "rb" / "sig.policy.json").partial.startswith("interrupted")
    verified = verify_recording(path)  # up to where the signal stopped it (was a false FAIL at that round)
    assert verified.ok and verified.stopped == f"interrupted ({sig.name})", [c.mismatches[:2] for c in verified.checks]


def test_a_signal_after_the_last_round_says_the_session_completed(tmp_path):
    """A session signalled after its game had played every round said "interrupted (SIGTERM) after 3 of 3
    rounds", as if cut short, of a recording that verify and rebuild take whole (a new researcher's trial).
    It is complete: the line says so and that nothing was undone; the status is the signal's, as every
    verb's after its work was done (README). The session waits for its external learner to leave, a
    process held stopped here (SIGSTOP) once it has settled every suggestion's reward (its last events
    are the session's: frozen before them, the file lacks them), so the signal surely comes after the
    last round and the learner's last update."""
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    p = subprocess.Popen([sys.executable, "-m", "pairplay", "session", "--participant", "sim:wasim", "--rounds", "3",
                          "--session", "late", "--external", "learner", "--out", str(tmp_path)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    learner = watcher = None
    try:
        while "bus listening" not in (line := p.stdout.readline()):
            assert p.poll() is None
        endpoint = line.split(" - ")[0].split()[-1]
        watcher = Bus(BusOptions(mode="client", connect=[endpoint]))
        ends = collect(watcher, event_key("late", "game", "SessionEnded"))
        made = collect(watcher, event_key("late", "learner", "SuggestionMade"))
        rewarded = collect(watcher, event_key("late", "learner", "RewardGiven"))
        learner = subprocess.Popen([sys.executable, "-m", "pairplay", "run", "learner", "--session", "late",
                                    "--connect", endpoint, "--quiet"], stdout=subprocess.DEVNULL, env=env)
        ends.get(timeout=120)
        assert wait_until(lambda: made.qsize() == rewarded.qsize(), 60)  # every suggestion settled
        time.sleep(0.5)  # the rest of the settling's events (QUpdated) follow its RewardGiven at once
        learner.send_signal(signal.SIGSTOP)  # its token stays: the session waits for it to leave
        p.send_signal(signal.SIGTERM)
        out, err = p.communicate(timeout=30)
    finally:
        for proc in (p, learner):
            if proc is not None and proc.poll() is None:
                proc.send_signal(signal.SIGCONT)
                proc.kill()
                proc.wait()
        if watcher is not None:
            watcher.close()
    path = tmp_path / "late.mcap"
    assert p.returncode == 143, (out, err)
    assert err.splitlines() == [f"pairplay session: interrupted (SIGTERM) after the session had completed all 3 rounds; recorded "
                                f"{len(read_log(path).events)} events to {path}; nothing was undone"], err
    [end] = ended(path)
    assert end.reason == "completed" and end.rounds_played == 3
    verified = verify_recording(path)
    assert verified.ok and rebuild_recording(path).partial == "", [(c.service, c.mismatches[:2], c.extra) for c in verified.checks]


def test_an_experimenter_stop_is_recorded_as_aborted(tmp_path):
    config = SessionConfig(session="abort", participant="sim:blind", persona="blind", seed=1, rounds=100000)
    stop, nodes = threading.Event(), {}

    def experimenter():  # stops it once the learner has learned something: mid-session, not at a fixed time
        wait_until(lambda: "learner" in nodes and nodes["learner"].driver.seq > 10, 30)
        stop.set()
    threading.Thread(target=experimenter, daemon=True).start()
    path = run_session(config, tmp_path / "abort.mcap", stop=stop, nodes_out=nodes)
    [end] = ended(path)
    assert end.reason == "aborted" and end.detail == "stopped by the experimenter" and end.rounds_played >= 0
    if end.rounds_played == 0:  # stopped in round 1: nothing to rebuild, said so (replay/check.py no_whole_round)
        with pytest.raises(NoWholeRound, match=r"the session ended \(aborted \(stopped by the experimenter\)\)"):
            rebuild_recording(path)
    else:
        assert "aborted" in rebuild_recording(path).partial


def test_a_signal_whose_deadline_passed_before_the_recorder_wrote_its_last_batch_still_finishes_the_file(
        tmp_path, monkeypatch):
    """The recorder's thread writes the session's last events while the shutdown goes on; on a loaded machine
    (load 20-29) the signal's deadline had passed when the session joined that thread, so the join gave up at
    once and the file was finished under a batch still being written: "write to closed file" (the session
    said it failed) or a file that is not whole (test_session_end[SIGTERM], 1 of ~4 runs with the process
    frozen right after its signal). The recorder's writing is this process's own work, not a wait on another:
    it is finished before the file is. Here the deadline has passed when the stop comes (as after a freeze)
    and the recorder's first write after it is slow (held 0.5 s)."""
    from pairplay.services.bus import Deadline
    from pairplay.services.recorder import Recorder

    config = SessionConfig(session="late", participant="sim:blind", persona="blind", seed=1, rounds=100000)
    stop, nodes, slowed = threading.Event(), {}, []
    take = Recorder._take

    def slow_take(self, item):  # on the recorder's thread: mid-session, the signal comes while it writes
        if not slowed and "learner" in nodes and nodes["learner"].driver.seq > 10:
            slowed.append(item)
            stop.why, stop.deadline = "SIGTERM", Deadline(0.0)  # its deadline ran out before the process ran on
            stop.set()
            time.sleep(0.5)  # the batch under way, as on a starved machine
        return take(self, item)
    monkeypatch.setattr(Recorder, "_take", slow_take)
    path = run_session(config, tmp_path / "late.mcap", stop=stop, nodes_out=nodes)
    assert slowed
    log = read_log(path)
    assert log.whole, log.error
    assert log.metadata["pairplay.recorder.end"]["stopped_by"] == "SIGTERM"
    [end] = ended(path)  # the session's own end is in its file, whatever the deadline left
    assert (end.reason, end.detail) == ("interrupted", "SIGTERM"), end


def test_a_service_that_leaves_and_does_not_come_back_fails_the_session(tmp_path):
    """The learner runs on its own Zenoh session (as another process would) and vanishes mid-session."""
    from pairplay.services.learner import LearnerLogic
    from pairplay.services.runner import Node

    config = SessionConfig(session="svcfail", participant="sim:deaf", persona="deaf", seed=2, rounds=100000)
    ready, box = threading.Event(), {}

    def on_bus(bus):
        box["bus"] = bus
        ready.set()

    t = threading.Thread(target=lambda: box.setdefault("path", run_session(
        config, tmp_path / "svcfail.mcap", external=("learner",), on_bus=on_bus, settle_timeout_s=1.0)))
    t.start()
    assert ready.wait(30)
    learner_bus = Bus(BusOptions(listen=[], connect=box["bus"].locators()))
    learner_stop = threading.Event()
    try:
        node = Node(learner_bus, LearnerLogic(), "svcfail")
        node.start()
        node.run_in_thread(learner_stop)
        assert wait_until(lambda: node.driver.seq > 10, 30)  # mid-session: it has learned something
    finally:
        learner_stop.set()
        learner_bus.close()  # its token goes with it: the learner is gone for good
    t.join(60)
    assert not t.is_alive()
    [end] = ended(box["path"])
    assert end.reason == "failed" and "learner left the bus" in end.detail


def test_recover_marks_what_it_completed_and_rebuild_flags_the_policy(tmp_path):
    config = SessionConfig(session="cut", participant="sim:blind", persona="blind", seed=3, rounds=6)
    path = run_session(config, tmp_path / "cut.mcap")
    data = path.read_bytes()
    cut = tmp_path / "cut-short.mcap"
    cut.write_bytes(data[:len(data) // 2])
    done = recover(cut)
    meta = read_log(done.output).metadata["pairplay.recovered"]
    assert meta["truncated"] == "true" and meta["session_ended"] == "false" and "pairplay recover" in meta["completed"]
    assert int(meta["last_round"]) == done.last_round >= 0 and not done.ended
    rebuilt = rebuild_recording(done.output)
    assert "no SessionEnded" in rebuilt.partial and "completed by pairplay recover: recovered from a cut file (cut-short.mcap): the events after its cut are lost" in rebuilt.partial
    [policy] = [p for p in write_outputs(rebuilt, tmp_path / "rb") if p.name.endswith(".policy.json")]
    assert "pairplay recover" in read_policy(policy).partial
    whole = rebuild_recording(path)
    assert whole.partial == "" and json.loads(Path(write_outputs(whole, tmp_path / "rb2")[0]).read_text()
                                              )["partial"] == ""


def test_old_recordings_end_without_the_new_fields_and_read_as_before():
    [end] = ended(SAMPLES / "sim-ashley.mcap")
    assert end.reason == "completed" and end.round == -1 and end.detail == ""
    assert rebuild_recording(SAMPLES / "sim-ashley.mcap").partial == ""


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_session_stopped_before_its_game_started_records_why_it_holds_no_session(tmp_path, sig, pairplay_cli):
    """The game waits for an external learner that never comes; the signal ends the wait. No
    SessionEnded can be recorded for a session never started, so the recorder's last record says it."""
    p = subprocess.Popen([sys.executable, "-m", "pairplay", "session", "--participant", "sim:wasim", "--session",
                          "early", "--external", "learner", "--out", str(tmp_path)], stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, text=True, env=dict(os.environ, PYTHONUNBUFFERED="1"))
    try:
        while "bus listening" not in p.stdout.readline():
            assert p.poll() is None
        time.sleep(0.5)
        p.send_signal(sig)
        out, _ = p.communicate(timeout=30)
    finally:
        if p.poll() is None:
            p.kill()
    assert signals.said(sig) in out, out  # the verb's line: Ctrl-C for SIGINT (pairplay/signals.py said)
    path = tmp_path / "early.mcap"
    log = read_log(path)
    assert log.whole and ended(path) == []
    assert log.metadata["pairplay.recorder.end"]["stopped_by"] == sig.name
    assert log.metadata["pairplay.recorder.end"]["session_ended"] == "false"
    r = pairplay_cli("rebuild", path, "--out", tmp_path / "rb")  # what it says, not how a process starts
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert r.stderr.startswith("pairplay rebuild: holds no session: ") and \
        f"no SessionStarted (stopped ({sig.name}) before its game started) ({path})" in r.stderr, r.stderr
    assert not (tmp_path / "rb").exists()


def test_a_recording_stopped_before_any_event_came_still_says_why(tmp_path):
    """A signal during the game's wait, before any service's announcement reached the recorder (a loaded
    machine): the file holds no message, but its end record says what stopped it, and rebuild says so
    too (it said "an MCAP file with no messages: the recording holds nothing": 1 of ~5 loaded suite runs)."""
    from pairplay.replay.rebuild import RebuildError
    from pairplay.services.recorder import Recorder

    recorder = Recorder(None, "early", tmp_path / "early.mcap")
    assert recorder.close(stopped_by="SIGTERM") is None
    with pytest.raises((RebuildError, ValueError), match=r"no SessionStarted \(stopped \(SIGTERM\) before its game "
                                                         r"started\)"):
        rebuild_recording(tmp_path / "early.mcap")


def test_every_recording_ends_with_how_it_ended(tmp_path):
    config = SessionConfig(session="done", participant="sim:blind", persona="blind", seed=1, rounds=2)
    end = read_log(run_session(config, tmp_path / "done.mcap")).metadata["pairplay.recorder.end"]
    assert end["session_ended"] == "true" and end["stopped_by"] == "" and int(end["ended_ns"]) > 0
