"""A second signal in the window between "the recording is whole" and "the user was told" (a new user's trial).

Each verb that records is a real `pairplay` process on loopback; it gets a first signal, then is held at a
named moment of its shutdown (pairplay/testpause.py, PAIRPLAY_TEST_PAUSE: test-only), gets its second signal
there, and is let go. What it then says must be true of the file the disk holds:

- held once its recording was finished (`recording-finished`: session, lab, run recorder), the second signal
  cuts nothing: the verb says its summary line (it said "interrupted (Ctrl-C); nothing more was written",
  with no summary, of a whole recording: once in 6 runs of the trial);
- held once a verb's output is in place (`folder-written`, pairplay/outputs.py), a Ctrl-C that stops the verb
  says the output is there, whole (it said "nothing more was written" of a folder `rebuild` had written);
- held between the file's end and its journal's removal (`recorder-whole`, services/recorder.py `close`), the
  journal is removed all the same and the line says the recording is whole (a stale `<name>.mcap.journal`
  was left beside a whole file, and the line said it "may lack its end").
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from mcap.reader import make_reader

from pairplay.numbers import counted
from pairplay.replay.wal import wal_path

ROOT = Path(__file__).resolve().parents[1]
LIMIT_S = 300.0  # a safety net for a process that never gets there (a loaded machine), not a goal


class Held:
    """One verb's process, held at `moment` until the test lets it go (and at `then` after it, if given)."""

    def __init__(self, tmp: Path, moment: str, args: list[str], ready: str, then: str = "", hold: str = ""):
        """`hold`: a moment held for good (its go-file is never made), in whichever thread reaches it."""
        self.go, self.go_then = tmp / f"go-{moment}", tmp / f"go-{then}"
        pauses = f"{moment}:{self.go}" + (f";{then}:{self.go_then}" if then else "") + \
            (f";{hold}:{tmp / 'go-never'}" if hold else "")
        env = dict(os.environ, PYTHONUNBUFFERED="1", PAIRPLAY_TEST_PAUSE=pauses)
        self.then = then
        self.paused_then = threading.Event()
        self.proc = subprocess.Popen([sys.executable, "-m", "pairplay", *args], cwd=tmp, env=env, text=True,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        self.out: list[str] = []
        self.err: list[str] = []
        self.ready, self.paused = threading.Event(), threading.Event()
        self.readers = [threading.Thread(target=self._read, args=(self.proc.stdout, self.out, ready), daemon=True),
                        threading.Thread(target=self._read, args=(self.proc.stderr, self.err, ready), daemon=True)]
        for r in self.readers:
            r.start()

    def _read(self, stream, lines: list[str], ready: str) -> None:
        for line in stream:
            lines.append(line)
            if ready in line:
                self.ready.set()
            if line.startswith("pairplay-test: paused at"):
                self.paused.set()
            if self.then and line.rstrip("\n") == f"pairplay-test: paused at {self.then}":
                self.paused_then.set()
        self.ready.set()
        self.paused.set()  # ended: nothing more to wait for
        self.paused_then.set()

    def run(self, first: int, second: int) -> tuple[int, list[str]]:
        """First signal once ready, second once held; let go; its status and its stderr lines but the pause's."""
        assert self.ready.wait(LIMIT_S), "never ready"
        assert self.proc.poll() is None, "".join(self.out + self.err)
        self.proc.send_signal(first)
        assert self.paused.wait(LIMIT_S), "never held"
        assert self.proc.poll() is None, "".join(self.out + self.err)  # held, not gone
        return self._signal_and_let_go(second)

    def once(self, sig: int) -> tuple[int, list[str]]:
        """One signal once held (the verb's first); let go; as `run`."""
        assert self.paused.wait(LIMIT_S), "never held"
        assert self.proc.poll() is None, "".join(self.out + self.err)
        return self._signal_and_let_go(sig)

    def at_both(self, first: int, second: int) -> tuple[int, list[str]]:
        """`first` once held at the first moment, let go; `second` once held at `then`; as `run`."""
        assert self.paused.wait(LIMIT_S), "never held"
        assert self.proc.poll() is None, "".join(self.out + self.err)
        self.proc.send_signal(first)
        self.go.touch()
        assert self.paused_then.wait(LIMIT_S), "never held again"
        assert self.proc.poll() is None, "".join(self.out + self.err)
        self.go = self.go_then
        return self._signal_and_let_go(second)

    def _signal_and_let_go(self, sig: int) -> tuple[int, list[str]]:
        """`sig` to the held process, then its go-file; its status and its stderr lines but the pause's."""
        self.proc.send_signal(sig)
        self.go.touch()
        code = self.proc.wait(LIMIT_S)
        for r in self.readers:
            r.join(10)
        return code, [line.rstrip("\n") for line in self.err if not line.startswith("pairplay-test:")]


def whole(path: Path) -> bool:
    """The recording has its end (MCAP's summary and footer, read by the mcap library) and no journal beside it."""
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    return summary is not None and not wal_path(path).exists()


def session(tmp: Path, name: str) -> list[str]:
    return ["session", "--participant", "sim:ashley", "--rounds", "300", "--session", name, "--out", str(tmp / "rec")]


def test_a_second_ctrl_c_as_the_session_is_summed_up_leaves_its_summary(tmp_path):
    held = Held(tmp_path, "recording-finished", session(tmp_path, "told"), "bus listening")
    code, err = held.run(signal.SIGINT, signal.SIGINT)
    path = tmp_path / "rec" / "told.mcap"
    assert code == 130, err
    assert whole(path)
    assert len(err) == 1 and err[0].startswith("pairplay session: interrupted (Ctrl-C) "), err
    assert f"to {Path('rec') / 'told.mcap'}" in err[0] or str(path) in err[0], err
    assert "nothing more was written" not in err[0] and "Traceback" not in "".join(err), err


def test_a_recorders_second_ctrl_c_is_said_as_such_though_the_first_signals_thread_has_not_run(tmp_path):
    """The thread the first signal's handler starts (services/bus.py stop_on_signals: it sets the stop flag) runs
    late on a loaded machine. `run recorder`'s cut path read that flag: a second Ctrl-C before the thread ran was
    said as cli/main.py's "interrupted (Ctrl-C); nothing more was written" (as `protocol pilot`'s, once at load
    5.4). A recorder finishing as its session ended, its first signal's thread held for good (`signal-stopping`),
    the first signal as it starts to finish, the second before the file's end: the cut line, from what the
    handler itself noted (services/bus.py `signal_taken`)."""
    from test_faults import endpoint_of, first_line, session_proc

    game = session_proc(tmp_path, "--participant", "sim:ashley", "--rounds", "2", "--session", "late", "--external",
                        "recorder")
    try:
        args = ["run", "recorder", "--session", "late", "--out", str(tmp_path), "--connect",
                endpoint_of(first_line(game))]
        held = Held(tmp_path, "recorder-closing", args, "", then="recorder-ending", hold="signal-stopping")
        code, err = held.at_both(signal.SIGINT, signal.SIGINT)
    finally:
        game.kill()
        game.communicate()
    path = tmp_path / "late.mcap"
    assert code == 130, err
    # (its last line: a loaded machine may add a recorder's WARNING of suggestions the robot did not act on)
    assert err[-1].startswith(f"pairplay run recorder: interrupted again (Ctrl-C) while stopping; {path} "), err
    assert "nothing more was written" not in "".join(err) and "Traceback" not in "".join(err), err
    assert wal_path(path).exists()  # cut before its end: its journal kept for `pairplay recover`


def test_a_second_ctrl_c_between_the_files_end_and_its_journals_removal(tmp_path):
    held = Held(tmp_path, "recorder-whole", session(tmp_path, "cut"), "bus listening")
    code, err = held.run(signal.SIGINT, signal.SIGINT)
    path = tmp_path / "rec" / "cut.mcap"
    assert code == 130, err
    assert whole(path), sorted(p.name for p in path.parent.iterdir())  # its journal removed with its end
    assert len(err) == 1 and err[0].startswith("pairplay session: interrupted again (Ctrl-C) while stopping; "), err
    assert "the recording is whole" in err[0] and "may lack its end" not in err[0], err


def test_a_second_sigterm_to_a_recorder_as_it_finishes(tmp_path):
    held = Held(tmp_path, "recorder-whole", ["run", "recorder", "--session", "rec", "--out", str(tmp_path / "rec")],
                "listening")
    code, err = held.run(signal.SIGTERM, signal.SIGTERM)
    path = tmp_path / "rec" / "rec.mcap"
    assert code == 143, err
    assert whole(path), sorted(p.name for p in path.parent.iterdir())
    assert len(err) == 1 and err[0].startswith("pairplay run recorder: interrupted again (SIGTERM) while stopping; "), err
    assert "the recording is whole" in err[0], err


def test_a_second_ctrl_c_to_a_recorder_once_its_file_is_finished(tmp_path):
    held = Held(tmp_path, "recording-finished", ["run", "recorder", "--session", "rec", "--out",
                                                 str(tmp_path / "rec")], "listening")
    code, err = held.run(signal.SIGINT, signal.SIGINT)
    assert code == 130, err
    assert whole(tmp_path / "rec" / "rec.mcap")
    # (no session came: its line says the file holds none and keeps the id, tests/test_recorder_gone.py)
    assert len(err) == 1 and err[0].startswith("pairplay run recorder: stopped (Ctrl-C) before session rec started: "), err


def test_a_second_ctrl_c_as_the_lab_is_summed_up_leaves_its_summary(tmp_path):
    held = Held(tmp_path, "recording-finished", ["lab", "--participant", "human:p1", "--session", "lab", "--out",
                                                 str(tmp_path / "rec")], "bus listening")
    code, err = held.run(signal.SIGINT, signal.SIGINT)
    assert code == 130, err
    assert whole(tmp_path / "rec" / "lab.mcap")
    assert len(err) == 1 and err[0].startswith("pairplay lab: interrupted (Ctrl-C) before the session started"), err


def test_a_ctrl_c_once_a_verbs_outputs_are_in_place_says_they_are(tmp_path):
    sample = ROOT / "recordings" / "samples" / "sim-ashley.mcap"
    (tmp_path / "out").mkdir()
    held = Held(tmp_path, "folder-written", ["rebuild", str(sample), "--out", "out", "--no-plot"], "")
    code, err = held.once(signal.SIGINT)
    assert code == 130, err
    assert (tmp_path / "out" / "sim-ashley.policy.json").is_file()
    assert err == ["pairplay rebuild: interrupted (Ctrl-C); out was written whole before it and kept; nothing more "
                   "was written"], err


SAMPLE = ROOT / "recordings" / "samples" / "sim-ashley.mcap"
# verbs whose work is done when held at `exiting` (cli/main.py `_end`: the process's last step before its status
# is decided); each prints what it wrote first (-q not given)
ENDED = {
    "counterfactual": (["counterfactual", str(SAMPLE), "--seeds", "2", "--out", "cf"], "cf/counterfactual.md"),
    "rebuild": (["rebuild", str(SAMPLE), "--out", "out", "--no-plot"], "out/sim-ashley.policy.json"),
    "session": (["session", "--participant", "sim:ashley", "--rounds", "2", "--session", "s", "--out", "rec"],
                "rec/s.mcap"),
}


@pytest.mark.parametrize("verb, sig", [("counterfactual", signal.SIGINT), ("rebuild", signal.SIGTERM),
                                       ("session", signal.SIGINT)])
def test_a_signal_as_a_finished_verb_exits_says_it_came_after_the_work(tmp_path, verb, sig):
    """A new user's trial: a Ctrl-C 0.03-0.4 s after `counterfactual` had written its folder, the process still
    running (the interpreter's teardown: 1.3-3 s at load 14, SIGINT ignored), exited 0 with no line, 7 of 10
    times. Held at its last step, the signal gives its status and the line of a signal after the work."""
    args, output = ENDED[verb]
    held = Held(tmp_path, "exiting", args, "")
    code, err = held.once(sig)
    assert code == 128 + sig, err
    assert (tmp_path / output).is_file()
    said = "Ctrl-C" if sig == signal.SIGINT else "SIGTERM"
    assert err[-1:] == [f"pairplay {verb}: interrupted ({said}) after it had finished; nothing was undone"], err
    assert "Traceback" not in "".join(err), err
    assert held.out, "its result was printed before"


def test_a_ctrl_c_once_counterfactuals_folder_is_in_place_says_it_is(tmp_path):
    held = Held(tmp_path, "folder-written", ENDED["counterfactual"][0], "")
    code, err = held.once(signal.SIGINT)
    assert code == 130, err
    assert (tmp_path / "cf" / "counterfactual.md").is_file()
    assert err == ["pairplay counterfactual: interrupted (Ctrl-C); cf was written whole before it and kept; "
                   "nothing more was written"], err


@pytest.mark.parametrize("second", [signal.SIGINT, signal.SIGTERM])
def test_a_second_signal_as_an_interrupted_verb_exits_is_no_traceback(tmp_path, second):
    """A new user's trial at load 35: `counterfactual` ended with a KeyboardInterrupt traceback, exit 1, after its
    Ctrl-C (a second signal, or a copy of a held one sent again, met the handler that raises as the process ended:
    cli/main.py `_end`). Stopped once its folder was in place, then held as it exits, the second signal changes
    nothing: one line, the first signal's status."""
    held = Held(tmp_path, "folder-written", ENDED["counterfactual"][0], "", then="exiting")
    code, err = held.at_both(signal.SIGINT, second)
    assert code == 130, err
    assert err == ["pairplay counterfactual: interrupted (Ctrl-C); cf was written whole before it and kept; "
                   "nothing more was written"], err


def test_a_second_signal_after_a_forced_session_is_summed_up_says_what_the_disk_holds(tmp_path):
    """A new user's trial: a second Ctrl-C during `session --force` said the earlier recordings were "kept beside
    it, named *.replaced" while none was on disk (the game had started: --force replaced them). Held once the
    session is summed up (services/session.py: it is known the game started), SIGINT then SIGTERM (distinct
    signals: both are taken, in that order): the line says what the folder holds."""
    rec = tmp_path / "rec"
    rec.mkdir()
    earlier = rec / "s.mcap"
    earlier.write_bytes(SAMPLE.read_bytes())
    args = ["session", "--participant", "sim:ashley", "--rounds", "2", "--session", "s", "--out", "rec", "--force"]
    held = Held(tmp_path, "session-summed", args, "")
    assert held.paused.wait(LIMIT_S), "never held"
    assert held.proc.poll() is None, "".join(held.out + held.err)
    held.proc.send_signal(signal.SIGINT)
    code, err = held._signal_and_let_go(signal.SIGTERM)
    assert code == 130, err  # the first signal's status (cli/main.py)
    left = sorted(p.name for p in rec.iterdir())
    assert left == ["s.mcap"] and whole(earlier), left  # the new recording, whole; the earlier one replaced
    with open(earlier, "rb") as f:
        events = make_reader(f).get_summary().statistics.message_count
    assert err == [f"pairplay session: interrupted again (SIGTERM) while stopping; {Path('rec') / 's.mcap'} was "
                   f"finished before it: the recording is whole ({counted(events, 'event')}), its end written; the earlier "
                   "recordings are removed: the game had started, and --force replaced them"], err


@pytest.mark.parametrize("verb", ["session", "lab"])
def test_a_second_ctrl_c_as_the_recording_is_finished_counts_its_events(tmp_path, verb):
    """`lab`'s line of a recording finished before the second signal left out the count `session`'s gave (a new
    user's trial): both count what the file's end says."""
    args = (session(tmp_path, "n") if verb == "session" else
            ["lab", "--participant", "human:p1", "--session", "n", "--out", str(tmp_path / "rec")])
    held = Held(tmp_path, "recorder-whole", args, "bus listening")
    code, err = held.run(signal.SIGINT, signal.SIGINT)
    path = tmp_path / "rec" / "n.mcap"
    assert code == 130, err
    assert whole(path)
    with open(path, "rb") as f:
        events = make_reader(f).get_summary().statistics.message_count
    assert len(err) == 1 and err[0].endswith(f"was finished before it: the recording is whole "
                                             f"({counted(events, 'event')}), its end written"), err


def test_a_signal_once_a_sweeps_summary_is_in_place_says_it_is(tmp_path):
    """A sweep stopped once its summary folder was in place said only that its cells were kept, for the same
    command to resume from them: its summary, written whole, is said too."""
    (tmp_path / "grid.toml").write_text('seeds = 1\n[study]\npersonas = "blind"\ngames = 1\nrounds = 20\n'
                                        'eval_rounds = 5\n[grid]\nreward_bonus = ["correct", "consistent"]\n')
    held = Held(tmp_path, "folder-written", ["sweep", "grid.toml", "--out", "sw"], "")
    code, err = held.once(signal.SIGTERM)
    assert code == 143, err
    assert (tmp_path / "sw" / "sweep.md").is_file()
    assert err == [f"pairplay sweep: interrupted (SIGTERM); 2 of 2 cells finished, kept in {Path('sw') / 'cells'}; its "
                   f"summary {Path('sw') / 'sweep.md'} was written whole before it and kept; nothing more was written"], err


def test_a_signal_as_a_usage_mistake_exits_is_said_too(tmp_path):
    """argparse's refusal ends the command by SystemExit, which went through the interpreter's teardown, not
    cli/main.py `_end`: the same end as every verb's now, a signal there said."""
    held = Held(tmp_path, "exiting", ["study", "--bogus"], "")
    code, err = held.once(signal.SIGINT)
    assert code == 130, err
    assert err == ["pairplay study: unknown option --bogus (see pairplay study --help)",
                   "pairplay study: interrupted (Ctrl-C) after it had finished with status 2; nothing was undone"], err


def test_a_second_ctrl_c_before_the_session_started_does_not_send_to_recover(tmp_path):
    """A new user's trial: cut by a second Ctrl-C before its recording held a SessionStarted, the line said
    "pairplay recover X.mcap completes it", and recover then refused the file ("holds no session"). Held before
    the file's end is written (`recorder-ending`) of a session whose game waits for a board (no SessionStarted
    yet): the line says it holds no session and names the file and its journal to remove, and recover refuses it."""
    args = ["session", "--participant", "human:p1", "--session", "n", "--out", str(tmp_path / "rec")]
    held = Held(tmp_path, "recorder-ending", args, "bus listening")
    code, err = held.run(signal.SIGINT, signal.SIGINT)
    path = tmp_path / "rec" / "n.mcap"
    assert code == 130, err
    assert len(err) == 1 and "pairplay recover" not in err[0], err
    assert f"{path} holds no session" in err[0], err
    if wal_path(path).exists():
        assert err[0].endswith(f"there is nothing to recover, {path} and its journal {wal_path(path)} can be removed"), err
    else:
        assert err[0].endswith(f"there is nothing to recover, {path} can be removed"), err
    done = subprocess.run([sys.executable, "-m", "pairplay", "recover", str(path)], capture_output=True, text=True)
    assert done.returncode == 2 and "holds no session" in done.stderr, done.stderr


def test_a_forced_session_cut_twice_names_its_journal_and_recover_tells_it_from_the_earlier_files(tmp_path):
    """A new user's trial: a second Ctrl-C of `session --force` over an earlier recording kept it as s0.mcap.replaced
    and advised "mv s0.mcap.replaced s0.mcap, after removing what stands there", naming not the cut recording's
    journal s0.mcap.journal; left beside the earlier file, `pairplay recover s0.mcap` took it for the file's
    ("complete already; ... 0 events taken from its journal, N of its messages refused") and wrote a copy. The
    line and the next `session --force`'s refusal name the journal; recover of the earlier file with that journal
    left beside it says the journal is not this file's and writes nothing."""
    rec = tmp_path / "rec"
    first = subprocess.run([sys.executable, "-m", "pairplay", "session", "--participant", "sim:ashley", "--rounds", "2",
                            "--session", "s0", "--out", str(rec), "-q"], cwd=tmp_path, capture_output=True, text=True)
    assert first.returncode == 0, first.stderr
    path = rec / "s0.mcap"
    with open(path, "rb") as f:
        earlier = f.read()
    held = Held(tmp_path, "recorder-ending", [*session(tmp_path, "s0"), "--force"], "bus listening")
    code, err = held.run(signal.SIGINT, signal.SIGINT)
    assert code == 130, err
    assert (rec / "s0.mcap.replaced").read_bytes() == earlier and wal_path(path).exists(), sorted(rec.iterdir())
    assert len(err) == 1 and f"remove it and its journal {wal_path(path).name} and give them" in err[0], err
    again = subprocess.run([sys.executable, "-m", "pairplay", *session(tmp_path, "s0"), "--force"], cwd=tmp_path,
                           capture_output=True, text=True)
    assert again.returncode == 2, again.stderr
    assert ("mv s0.mcap.replaced s0.mcap, after removing s0.mcap and its journal s0.mcap.journal)"
            in again.stderr), again.stderr
    path.unlink()  # the advice half followed: the journal is left beside the earlier file
    (rec / "s0.mcap.replaced").rename(path)
    done = subprocess.run([sys.executable, "-m", "pairplay", "recover", str(path)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert "the journal beside it (s0.mcap.journal) is not this file's: it is of another recording of session 's0'" \
        in done.stdout and "nothing written" in done.stdout, done.stdout
    assert sorted(p.name for p in rec.iterdir()) == ["s0.mcap", "s0.mcap.journal"]
