"""Progress bars only on a terminal (cli/progress.py): a pipe or a file gets the verb's lines alone.

A new user's trial, 2026-12-01: `pairplay sweep` drew tqdm's bar (carriage returns, one redraw per
cell) into a captured stderr, ahead of its interrupted line; `pairplay study` did the same. Every
tqdm of the command line is made by cli/progress.py (the last test checks no verb makes its own)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

from pairplay.cli import progress

ROOT = Path(__file__).resolve().parents[1]
GRID = 'seeds = 1\n[study]\npersonas = "blind"\ngames = 1\nrounds = 20\neval_rounds = 5\n[grid]\ntrained_updates = [50]\n'


def test_a_bar_is_shown_on_a_terminal_only_and_never_with_quiet(monkeypatch):
    master, slave = os.openpty()
    r, w = os.pipe()
    try:
        with os.fdopen(slave, "w", closefd=False) as tty, os.fdopen(w, "w", closefd=False) as pipe:
            monkeypatch.setattr(sys, "stderr", tty)
            assert progress.shown(quiet=False) and not progress.shown(quiet=True)
            monkeypatch.setenv("TQDM_DISABLE", "1")  # tqdm's own switch, honoured
            assert not progress.shown(quiet=False)
            monkeypatch.delenv("TQDM_DISABLE")
            with progress.bar(3, "x", "cell", quiet=False) as bar:
                assert not bar.disable
            monkeypatch.setattr(sys, "stderr", pipe)
            assert not progress.shown(quiet=False)
            with progress.bar(3, "x", "cell", quiet=False) as bar:
                bar.update(3)
                assert bar.disable
            monkeypatch.setattr(sys, "stderr", None)  # pythonw, a closed stream: no terminal
            assert not progress.shown(quiet=False)
    finally:
        for fd in (master, slave, r, w):
            os.close(fd)


def test_sweep_and_study_through_a_pipe_write_no_bar(tmp_path):
    (tmp_path / "grid.toml").write_text(GRID)
    for argv in (["sweep", "grid.toml", "--out", "sw"],
                 ["study", "--train-only", "--personas", "blind", "--games", "1", "--rounds", "10", "--out", "st"]):
        r = subprocess.run([sys.executable, "-m", "pairplay", *argv], cwd=tmp_path, capture_output=True, text=True,
                           timeout=300)
        assert r.returncode == 0, r.stderr
        assert "\r" not in r.stderr and "it/s" not in r.stderr and "cell/s" not in r.stderr and \
            "round/s" not in r.stderr, (argv[0], r.stderr)


def test_every_tqdm_of_the_command_line_is_made_by_cli_progress():
    makers = [p.relative_to(ROOT).as_posix() for folder in ("cli", "report", "services", "bench", "replay", "core")
              for p in (ROOT / folder).rglob("*.py") if re.search(r"\btqdm\(", p.read_text())]
    assert makers == ["cli/progress.py"], makers
