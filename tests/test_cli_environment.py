"""pairplay's environment variables (pairplay/environment.py): a value they cannot take is one line, exit 2.

`PAIRPLAY_THREADS=abc` and `=0` were ignored without a word (a study ran on every core, exit 0: a new user's
trial); `PAIRPLAY_WAIT_FOR_S=abc` was a ValueError traceback as the runner's module loaded. Each case is the
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
])
def test_a_value_the_variable_cannot_take_is_one_line_naming_it(tmp_path, name, value, words):
    r = _pairplay(tmp_path, {name: value}, "combine", "nope.json")
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert len(lines) == 1 and lines[0].startswith(f"pairplay combine: {words}") and "unset it" in lines[0], lines


@pytest.mark.parametrize("env", [{"PAIRPLAY_THREADS": "1"}, {"PAIRPLAY_THREADS": ""}, {"PAIRPLAY_WAIT_FOR_S": "2.5"}])
def test_a_value_it_takes_or_none_lets_the_verb_run(tmp_path, env):
    r = _pairplay(tmp_path, env, "combine", "nope.json")  # the verb's own refusal: it ran
    assert r.returncode == 2 and r.stderr.strip() == "pairplay combine: no such policy file or folder (nope.json)", r.stderr


def test_the_threads_and_the_wait_are_the_values_given(monkeypatch):
    from pairplay import environment
    monkeypatch.setenv("PAIRPLAY_THREADS", "3")
    monkeypatch.setenv("PAIRPLAY_WAIT_FOR_S", "240")
    assert (environment.threads(), environment.wait_for_s()) == (3, 240.0)
    monkeypatch.delenv("PAIRPLAY_THREADS")
    monkeypatch.delenv("PAIRPLAY_WAIT_FOR_S")
    assert (environment.threads(), environment.wait_for_s()) == (None, environment.WAIT_FOR_S)
