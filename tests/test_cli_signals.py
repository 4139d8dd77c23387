"""One exit rule for a signal, every verb, every moment: 128 + its number (130 SIGINT, 143 SIGTERM).

Before (a new user's trial, 2026-11-30): a session, lab, replay or view
interrupted once running exited 0 ("as asked") and 130 before its bus; the
router exited 130 on SIGINT and 0 on SIGTERM; a verb without its own handler
(study) was killed by SIGTERM outright. Each verb here is started and
signalled early (while it loads, before its first line) or while it runs
(after its first line); tests/test_faults_signals.py signals the bus verbs in
their running states and checks the same status. The processes run side by
side (each its own), so the table takes the time of its slowest rows.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import pytest

from pairplay import signals
from pairplay.cli.main import main
from pairplay.cli.rebuild import MANIFEST

from busutil import wait_until
from rewrite_mcap import another_session

SAMPLE = Path(__file__).resolve().parents[1] / "recordings" / "samples" / "sim-ashley.mcap"


@dataclass
class Row:
    name: str
    args: list[str]
    sig: signal.Signals
    early: bool  # signalled as soon as the command's handlers exist (it then loads its verb), else after its first line
    first: str = ""  # a piece of the first stdout line (running rows)


ROWS = [
    Row("session early", ["session", "--participant", "sim:blind", "--rounds", "1000", "--session", "e1", "--out", "rec"],
        signal.SIGINT, True),
    Row("lab early", ["lab", "--participant", "human:p1", "--session", "e2", "--out", "rec"], signal.SIGTERM, True),
    Row("router early", ["router", "--listen", "tcp/127.0.0.1:0"], signal.SIGTERM, True),
    Row("replay early", ["replay", "rec.mcap", "--speed", "0.01"], signal.SIGINT, True),
    Row("study early", ["study", "--quiet", "--out", "st"], signal.SIGTERM, True),
    Row("protocol serve early", ["protocol", "serve", "study"], signal.SIGINT, True),
    Row("run learner early", ["run", "learner", "--session", "e3"], signal.SIGTERM, True),
    Row("router running SIGINT", ["router", "--listen", "tcp/127.0.0.1:0"], signal.SIGINT, False, "listening"),
    Row("router running SIGTERM", ["router", "--listen", "tcp/127.0.0.1:0"], signal.SIGTERM, False, "listening"),
    Row("replay running SIGTERM", ["replay", "rec.mcap", "--speed", "0.01"], signal.SIGTERM, False, "replaying"),
    Row("session running", ["session", "--participant", "sim:blind", "--rounds", "5000", "--session", "r1",
                            "--out", "rec"], signal.SIGTERM, False, "bus listening"),
    Row("run learner running", ["run", "learner", "--session", "r2"], signal.SIGINT, False, "listening"),
    Row("robot running", ["robot", "--session", "r3", "--robot", "virtual"], signal.SIGTERM, False, "robot bridge"),
]


def _handlers_installed(pid: int, timeout_s: float = 60.0) -> bool:
    """Wait until the process catches SIGTERM (cli/start.py installs its handlers first of all):
    a signal before that meets the interpreter's own start-up, which no code of ours can answer."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            status = Path(f"/proc/{pid}/status").read_text()
        except OSError:
            return False
        caught = int(next(line.split()[1] for line in status.splitlines() if line.startswith("SigCgt:")), 16)
        if caught >> (signal.SIGTERM - 1) & 1:
            return True
        time.sleep(0.005)
    return False


def _run(row: Row, template: Path, base: Path) -> tuple[Row, subprocess.CompletedProcess, float]:
    root = base / row.name.replace(" ", "_")
    shutil.copytree(template, root)
    p = subprocess.Popen([sys.executable, "-m", "pairplay", *row.args], cwd=root, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env=dict(os.environ, PYTHONUNBUFFERED="1"))
    out = []
    try:
        if row.early:
            assert _handlers_installed(p.pid), row.name
        else:
            reader = threading.Thread(target=lambda: out.append(p.stdout.readline()), daemon=True)
            reader.start()
            reader.join(120)
            assert out and row.first in out[0], (row.name, out)
        p.send_signal(row.sig)
        t0 = time.monotonic()
        rest, err = p.communicate(timeout=60)
        took = time.monotonic() - t0
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    return row, subprocess.CompletedProcess(p.args, p.returncode, "".join(out) + rest, err), took


@pytest.fixture(scope="module")
def ran(tmp_path_factory):
    template = tmp_path_factory.mktemp("template")
    shutil.copy(SAMPLE, template / "rec.mcap")
    assert main(["protocol", "init", str(template / "study"), "--study", "thesis-ch7", "--quiet"]) == 0
    base = tmp_path_factory.mktemp("rows")
    with ThreadPoolExecutor(max_workers=4) as pool:
        return {row.name: (r, took) for row, r, took in pool.map(lambda row: _run(row, template, base), ROWS)}


@pytest.mark.parametrize("row", ROWS, ids=[r.name for r in ROWS])
def test_a_signal_ends_a_verb_with_128_plus_its_number_at_any_moment(row, ran):
    r, took = ran[row.name]
    assert r.returncode == 128 + row.sig, (row.name, r.returncode, r.stdout[-800:], r.stderr[-800:])
    assert "Traceback" not in r.stderr + r.stdout, r.stderr
    # ONE line says the stop, on stderr, `pairplay <verb>: ...` as every one-line message (the session's, the
    # lab's, view's, replay's and the router's had no prefix; `run` and `robot` said nothing at all); one
    # before the verb is known (`pairplay` alone) is `pairplay: ...`
    said = [line for line in r.stderr.splitlines() if row.sig.name in line or "Ctrl-C" in line]
    assert len(said) == 1 and said[0].startswith((f"pairplay {row.args[0]}", "pairplay: ")), (row.name, r.stderr[-800:])


@pytest.fixture
def command_handlers():
    """The pairplay command's own SIGINT/SIGTERM handlers (cli/main.py installs them for the command), for an
    in-process main(); pytest's come back after (main restores what it found)."""
    from pairplay.cli.interrupts import DeferredInterrupt
    from pairplay.signals import SIGNALS
    saved = {s: signal.getsignal(s) for s in SIGNALS}
    DeferredInterrupt().install()
    yield
    for s, handler in saved.items():
        signal.signal(s, handler)


def _signal_after(monkeypatch, module, name: str, sig: signal.Signals) -> None:
    """`module.name` runs, then the process gets `sig` (a real signal, to this process)."""
    original = getattr(module, name)

    def then_signal(*args, **kwargs):
        result = original(*args, **kwargs)
        os.kill(os.getpid(), sig)
        return result
    monkeypatch.setattr(module, name, then_signal)


def _files(root: Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.rglob("*")}


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP], ids=["SIGINT", "SIGTERM", "SIGHUP"])
def test_rebuild_interrupted_part_way_leaves_nothing_it_created_not_even_its_folder(
        sig, tmp_path, monkeypatch, capsys, command_handlers):
    """Before: the outputs were removed but the --out folder rebuild had made stayed, empty. SIGHUP (the terminal
    closed) killed it outright, no line, 129 by the signal (a hostile user's trial): now stopped as SIGTERM stops it."""
    import pairplay.replay.rebuild as rebuild
    shutil.copy(SAMPLE, tmp_path / "a.mcap")
    before = _files(tmp_path)
    _signal_after(monkeypatch, rebuild, "write_outputs", sig)  # one recording's outputs are written
    assert main(["rebuild", str(tmp_path / "a.mcap"), "--out", str(tmp_path / "new" / "deeper")]) == 128 + sig
    out, err = capsys.readouterr()
    assert _files(tmp_path) == before
    assert out == ""  # no result line for outputs that were removed
    said = "Ctrl-C" if sig == signal.SIGINT else sig.name
    assert err.splitlines() == [f"pairplay rebuild: interrupted ({said}); nothing more was written"]


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_rebuild_force_interrupted_part_way_leaves_the_earlier_policies_all_of_them(
        sig, tmp_path, monkeypatch, capsys, command_handlers):
    """Before (a new user's trial): `rebuild --out DIR --force` replaced its outputs one by one, so a
    Ctrl-C after the first recording's left DIR holding its new policy beside the second's old one.
    Now everything is written beside DIR first and moved in as a whole (outputs.output_folder)."""
    import pairplay.replay.rebuild as rebuild
    for k, name in enumerate(("a", "b")):  # two sessions (one session in two files is refused: replay/onesession.py)
        another_session(tmp_path / f"{name}.mcap", k, SAMPLE)
    out = tmp_path / "out"
    out.mkdir()
    earlier = {f"{n}.{kind}": "earlier run" for n in ("a", "b") for kind in ("policy.json", "curve.csv")}
    earlier |= {"learning-curves.png": "earlier run", "notes.txt": "the user's"}
    for name, text in earlier.items():
        (out / name).write_text(text)
    _signal_after(monkeypatch, rebuild, "write_outputs", sig)  # after the first recording's outputs
    args = ["rebuild", str(tmp_path / "a.mcap"), str(tmp_path / "b.mcap"), "--out", str(out), "--force"]
    assert main(args) == 128 + sig
    assert {p.name: p.read_text() for p in out.iterdir()} == earlier
    assert {p.name for p in tmp_path.iterdir()} == {"a.mcap", "b.mcap", "out"}  # no staging folder left
    monkeypatch.undo()
    assert main(args) == 0  # uninterrupted, every output is the new run's and the user's file stays
    assert {p.name for p in out.iterdir()} == set(earlier) | {MANIFEST}  # (the files it wrote: cli/rebuild.py)
    assert [n for n in earlier if (out / n).read_bytes() == b"earlier run"] == []


def test_rebuild_interrupted_keeps_a_folder_that_was_there(tmp_path, monkeypatch, capsys, command_handlers):
    import pairplay.cli.rebuild as cli_rebuild
    shutil.copy(SAMPLE, tmp_path / "a.mcap")
    (tmp_path / "out").mkdir()
    _signal_after(monkeypatch, cli_rebuild, "plot_curves", signal.SIGINT)  # everything but the result line
    assert main(["rebuild", str(tmp_path / "a.mcap"), "--out", str(tmp_path / "out")]) == 130
    assert list((tmp_path / "out").iterdir()) == []


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_after_the_work_is_done_exits_128_plus_n_saying_the_work_is_complete(
        sig, tmp_path, monkeypatch, capsys, command_handlers):
    """Before: 130 with no line at all (a signal just after rebuild had written everything), or "nothing
    more was written" said of outputs that were all there. Now: the results stand, are printed, and one
    line says the signal came after the verb had finished; the status is still the signal's."""
    import builtins

    import pairplay.cli.rebuild as cli_rebuild
    shutil.copy(SAMPLE, tmp_path / "a.mcap")
    _signal_after(monkeypatch, builtins, "print", sig)  # while it prints its result: the work is done
    assert main(["rebuild", str(tmp_path / "a.mcap"), "--out", str(tmp_path / "out")]) == 128 + sig
    monkeypatch.undo()
    out, err = capsys.readouterr()
    assert "a.mcap: " in out and "learning-curves.png" in out
    assert {p.name for p in (tmp_path / "out").iterdir()} == {"a.policy.json", "a.curve.csv", "learning-curves.png",
                                                               MANIFEST}
    said = "Ctrl-C" if sig == signal.SIGINT else "SIGTERM"
    assert err.splitlines() == [f"pairplay rebuild: interrupted ({said}) after it had finished; nothing was undone"]
    assert cli_rebuild  # the verb's module was the one run


@pytest.mark.parametrize("verb", ["rebuild", "recover", "combine"])
def test_every_verb_a_signal_after_its_run_returned_is_one_line_and_its_status(
        verb, tmp_path, monkeypatch, capsys, command_handlers):
    """The same rule for every verb: the signal arrives once the verb's run() returned."""
    shutil.copy(SAMPLE, tmp_path / "a.mcap")
    assert main(["rebuild", str(tmp_path / "a.mcap"), "--out", str(tmp_path / "rb"), "--no-plot"]) == 0
    policy = str(tmp_path / "rb" / "a.policy.json")
    if verb == "combine":  # a merge takes two or more policies of a participant (algorithm 3's profile)
        import msgspec
        from pairplay.schemas.policy import read_policy, write_policy
        first = read_policy(policy)
        write_policy(tmp_path / "b.json", msgspec.structs.replace(first, q=[[v + 0.5 for v in row] for row in first.q]))
    args = {"rebuild": ["rebuild", str(tmp_path / "a.mcap"), "--out", str(tmp_path / "rb2"), "--no-plot"],
            "recover": ["recover", str(tmp_path / "a.mcap"), "--out", str(tmp_path / "r.mcap")],
            "combine": ["combine", policy, str(tmp_path / "b.json"), "-o", str(tmp_path / "m.json")]}[verb]
    capsys.readouterr()
    import pairplay.cli.main as cli_main
    _signal_after(monkeypatch, cli_main, "signal_received", signal.SIGTERM)  # asked as soon as run() returned
    code = main(args)
    out, err = capsys.readouterr()
    lines = err.splitlines()
    assert code == 143, (out, err)
    assert len(lines) == 1 and lines[0].startswith(f"pairplay {verb}: interrupted (SIGTERM) after it had finished"), err


GRID = 'seeds = 2\n[study]\npersonas = "blind"\ngames = 1\nrounds = 20\neval_rounds = 10\n[grid]\ntrained_updates = [50]\n'


def test_a_sweep_interrupted_before_any_cell_leaves_nothing(tmp_path, monkeypatch, capsys, command_handlers):
    """Before: its folder stayed with grid.toml and an empty cells/."""
    import pairplay.cli.sweep as cli_sweep
    (tmp_path / "grid.toml").write_text(GRID)
    before = _files(tmp_path)

    def stopped(grid, out, **kw):
        (Path(out) / "cells").mkdir(parents=True, exist_ok=True)
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(5)  # the signal lands here
    monkeypatch.setattr(cli_sweep, "run_sweep", stopped)
    assert main(["sweep", str(tmp_path / "grid.toml"), "--out", str(tmp_path / "sw" / "deep"), "--quiet"]) == 143
    assert _files(tmp_path) == before
    assert capsys.readouterr().err.splitlines() == ["pairplay sweep: interrupted (SIGTERM); nothing more was written"]


def test_a_sweep_interrupted_after_its_cells_keeps_them_and_says_so(tmp_path, monkeypatch, capsys, command_handlers):
    import pairplay.cli.sweep as cli_sweep
    (tmp_path / "grid.toml").write_text(GRID)
    out = tmp_path / "sw"
    _signal_after(monkeypatch, cli_sweep, "run_sweep", signal.SIGINT)  # the cells are done, the tables not
    assert main(["sweep", str(tmp_path / "grid.toml"), "--out", str(out), "--quiet"]) == 130
    err = capsys.readouterr().err.splitlines()
    assert err == [f"pairplay sweep: interrupted (Ctrl-C); 2 of 2 cells finished, kept in {out / 'cells'}: "
                   "the same command resumes from them"], err
    assert len(list((out / "cells").glob("*.json"))) == 2
    monkeypatch.undo()
    assert main(["sweep", str(tmp_path / "grid.toml"), "--out", str(out)]) == 0  # resumes: 0 computed (-q: silent)
    assert "0 computed" in capsys.readouterr().out


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_second_signal_while_a_session_stops_cuts_its_shutdown_whichever_it_is(tmp_path, sig):
    """The README says a second SIGTERM while a session stops cuts it short as a second Ctrl-C does; a new user's
    trial sent two SIGTERMs 0.02-0.3 s apart 11 times and never saw it: the handler raised only on a second
    SIGINT, and a second SIGTERM was heard only in the waits that look for it (signals.wait_cut)."""
    p = subprocess.Popen([sys.executable, "-m", "pairplay", "session", "--participant", "sim:blind", "--rounds",
                          "5000", "--session", "tw", "--out", "rec"], cwd=tmp_path, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env=dict(os.environ, PYTHONUNBUFFERED="1"))
    try:
        first = p.stdout.readline()
        assert "bus listening" in first, first
        # the game under way (its stop takes ~0.3 s; one before it started takes ~0.02 s): its second round
        # in the recorder's journal (a fixed 1-s sleep was before the game's start at load 17-30: "interrupted
        # before the session started", twice in helpers' suites)
        journal = tmp_path / "rec" / "tw.mcap.journal"  # (it holds each event's payload, its tag in it)
        assert wait_until(lambda: journal.exists() and b"RoundEnded" in journal.read_bytes(), 60)
        p.send_signal(sig)
        time.sleep(0.03)  # (two at once are one: the kernel keeps one pending signal of a kind)
        p.send_signal(sig)  # the first one's shutdown takes ~0.3 s
        _, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    assert p.returncode == 128 + sig, (p.returncode, err)
    assert f"interrupted again ({signals.said(sig)}) while stopping" in err, err
