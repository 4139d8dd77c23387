"""pairplay's environment variables (pairplay/environment.py): a value they cannot take is one line, exit 2.

`PAIRPLAY_THREADS=abc` and `=0` were ignored without a word (a study ran on every core, exit 0: a new user's
trial); `PAIRPLAY_WAIT_FOR_S=abc` was a ValueError traceback as the runner's module loaded. PAIRPLAY_SETTLE_S
(the settle time, 2026-12-03) is read the same way. Each case is the
command as a user runs it, a process of its own.
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest


def _pairplay(tmp_path, env: dict[str, str], *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "pairplay", *args], cwd=tmp_path, capture_output=True, text=True,
                          env={**os.environ, **env}, timeout=300)


@pytest.mark.parametrize("name, value, words", [
    ("PAIRPLAY_THREADS", "abc", "PAIRPLAY_THREADS='abc' is not a positive integer"),
    ("PAIRPLAY_THREADS", "0", "PAIRPLAY_THREADS='0' is not a positive integer"),
    ("PAIRPLAY_THREADS", "-2", "PAIRPLAY_THREADS='-2' is not a positive integer"),
    ("PAIRPLAY_WAIT_FOR_S", "abc", "PAIRPLAY_WAIT_FOR_S='abc' is not a positive number of seconds"),
    ("PAIRPLAY_WAIT_FOR_S", "nan", "PAIRPLAY_WAIT_FOR_S='nan' is not a positive number of seconds"),
    ("PAIRPLAY_SETTLE_S", "abc", "PAIRPLAY_SETTLE_S='abc' is not a positive number of seconds: how long a session"),
    ("PAIRPLAY_SETTLE_S", "0", "PAIRPLAY_SETTLE_S='0' is not a positive number of seconds"),
])
def test_a_value_the_variable_cannot_take_is_one_line_naming_it(tmp_path, name, value, words):
    r = _pairplay(tmp_path, {name: value}, "combine", "nope.json")
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert len(lines) == 1 and lines[0].startswith(f"pairplay combine: {words}") and "unset it" in lines[0], lines


@pytest.mark.parametrize("env", [{"PAIRPLAY_THREADS": "1"}, {"PAIRPLAY_THREADS": ""}, {"PAIRPLAY_WAIT_FOR_S": "2.5"},
                                 {"PAIRPLAY_SETTLE_S": "2.5"}])
def test_a_value_it_takes_or_none_lets_the_verb_run(tmp_path, env):
    r = _pairplay(tmp_path, env, "combine", "nope.json")  # the verb's own refusal: it ran
    assert r.returncode == 2 and r.stderr.strip() == "pairplay combine: no such policy file or folder (nope.json)", r.stderr


def test_the_threads_the_wait_and_the_settle_time_are_the_values_given(monkeypatch):
    from pairplay import environment
    monkeypatch.setenv("PAIRPLAY_THREADS", "3")
    monkeypatch.setenv("PAIRPLAY_WAIT_FOR_S", "240")
    monkeypatch.setenv("PAIRPLAY_SETTLE_S", "7.5")
    assert (environment.threads(), environment.wait_for_s(), environment.settle_s()) == (3, 240.0, 7.5)
    monkeypatch.delenv("PAIRPLAY_THREADS")
    monkeypatch.delenv("PAIRPLAY_WAIT_FOR_S")
    monkeypatch.delenv("PAIRPLAY_SETTLE_S")
    assert (environment.threads(), environment.wait_for_s(), environment.settle_s()) == \
        (None, environment.WAIT_FOR_S, environment.SETTLE_S) == (None, 30.0, 30.0)


def test_the_settle_time_is_what_sessions_and_services_wait_for_a_gone_service():
    """The settle time a process reads at its start: the services' wait for a gone game (runner.GameWatch, `pairplay run
    game`'s for its recorder) and the default of every session's (run_session: `pairplay session`, the lab, protocol)."""
    code = ("import inspect; from pairplay.services import runner, session; "
            "print(runner.GAME_GONE_S, inspect.signature(session.run_session).parameters['settle_timeout_s'].default)")
    for env, said in (({"PAIRPLAY_SETTLE_S": "7.5"}, "7.5 7.5"), ({}, "30.0 30.0")):
        environ = {k: v for k, v in os.environ.items() if k != "PAIRPLAY_SETTLE_S"}
        r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env={**environ, **env},
                           timeout=300)
        assert r.returncode == 0 and r.stdout.split() == said.split(), r.stdout + r.stderr
