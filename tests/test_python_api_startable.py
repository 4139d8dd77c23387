"""run_session refuses, before any file or bus exists, every config `pairplay session` refuses before it starts.

A new user's trial: `run_session(SessionConfig(participant="sim:wasm", persona="wasm", ...), "r3.mcap")` opened
the bus, logged the participant's refusals, raised StartRefused (neither ValueError nor TypeError) and left
r3.mcap behind; a second call said "session r3 has a recording already; choose another --session" (the id was
"a", and a function has no --session); `participant="sim:ashley", persona="wasim"` ran. The CLI refuses all of
these up front (cli/session.py); run_session now does (services/session.py `startable`) for every caller.
"""

from __future__ import annotations

import pytest

import pairplay
from pairplay.errors import InputError
from pairplay.schemas.policy import N_STATES

BASE = dict(session="a", seed=0, rounds=2)

REFUSED = [  # (the config's fields, what the one line must say)
    (dict(participant="sim:wasm", persona="wasm"), "unknown persona 'wasm' (did you mean 'wasim'?)"),
    (dict(participant="sim:ashley", persona="wasim"), "disagree: give persona='ashley'"),
    (dict(participant="sim:ashly", persona="ashley"), "unknown persona 'ashly' (did you mean 'ashley'?)"),
    (dict(participant="robot:ashley", persona="ashley"), "use sim:<persona> or human:<id>"),
    (dict(participant="simm:ashley", persona="ashley"), "did you mean 'sim:ashley'?"),
    (dict(participant="human:p 1", ignore_rule="time", observed_source="first-pick"), "participant id 'p 1'"),
    (dict(participant="sim:ashley", persona="ashley", policy_actions=[0] * N_STATES), "would ignore them"),
    (dict(participant="sim:ashley", persona="ashley", algorithm="pi-reuse", policy_actions=[0] * N_STATES,
          learner={"reuse_rounds": 0}), "would never reuse the bias policy"),
]


@pytest.mark.parametrize("fields, words", REFUSED, ids=[w for _, w in REFUSED])
def test_refused_before_anything_exists(tmp_path, fields, words):
    path = tmp_path / "r3.mcap"
    with pytest.raises(InputError) as err:
        pairplay.run_session(pairplay.SessionConfig(**BASE, **fields), path)
    line = str(err.value)
    assert isinstance(err.value, ValueError) and "\n" not in line
    assert words in line and "pairplay.run_session(config)" in line
    assert list(tmp_path.iterdir()) == []  # no recording left behind: nothing started


def test_a_persona_by_another_spelling_still_runs_its_checks():
    # the participant service takes a persona by key or name, case-insensitive (core/personas.py persona)
    from pairplay.services.session import startable
    config = pairplay.SessionConfig(**BASE, participant="sim:Ashley", persona="ashley")
    startable(config)  # (no error)


def test_an_existing_recording_named_as_the_path_not_a_session(tmp_path):
    path = tmp_path / "r3.mcap"
    path.write_bytes(b"")
    config = pairplay.SessionConfig(**BASE, participant="sim:ashley", persona="ashley")
    with pytest.raises(pairplay.errors.OutputError) as err:
        pairplay.run_session(config, path)
    line = str(err.value)
    assert "r3.mcap" in line and "choose another path" in line
    assert "--session" not in line and "session r3" not in line
