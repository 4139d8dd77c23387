"""pairplay's own environment variables: read here, and a value they cannot take refused, never ignored.

Rule: PAIRPLAY_THREADS (a positive integer: the most threads a computation
uses, core/threads.py), PAIRPLAY_WAIT_FOR_S (a positive number of seconds:
how long a game waits for the services it needs, services/runner.py) and
PAIRPLAY_SETTLE_S (a positive number of seconds: the settle time, how long a
session or a service waits for a service that left the bus, the game or an
external recorder, to come back before it ends: services/runner.py
GAME_GONE_S) are read by `threads()`, `wait_for_s()` and `settle_s()`, which
give None / the default for a value
they cannot take, so that importing a module never fails on one. The command
line calls `check()` before a verb runs: such a value is a user's mistake, one
line, exit 2 (cli/main.py), naming the variable and what it takes.
`PAIRPLAY_THREADS=abc` and `=0` were ignored without a word and the study ran
on every core (a new user's trial). Empty counts as not set. Standard library only.
"""

from __future__ import annotations

import math
import os

from pairplay.errors import UserError

WAIT_FOR_S = 30.0  # a game's wait for its services when PAIRPLAY_WAIT_FOR_S is not set
SETTLE_S = 30.0  # the settle time when PAIRPLAY_SETTLE_S is not set (a test's dead recorder waits less)


def _threads(text: str) -> int:
    if not text.strip().isdigit() or int(text) < 1:
        raise ValueError("a positive integer: the most threads a computation uses (1 when studies share the machine)")
    return int(text)


def _seconds(what: str):
    """A parser of a positive, finite number of seconds; its refusal says `what` they are."""
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"a positive number of seconds: {what}")
        return value
    return parse


VARIABLES = {"PAIRPLAY_THREADS": _threads,
             "PAIRPLAY_WAIT_FOR_S": _seconds("how long a game waits for the services it needs"),
             "PAIRPLAY_SETTLE_S": _seconds("how long a session waits for a service that left the bus to come back")}


def _read(name: str):
    """The variable's value, None if it is not set (or empty) or cannot be taken (`check` says so)."""
    text = os.environ.get(name, "")
    if not text.strip():
        return None
    try:
        return VARIABLES[name](text)
    except ValueError:
        return None


def threads() -> int | None:
    """PAIRPLAY_THREADS, or None (every core)."""
    return _read("PAIRPLAY_THREADS")


def wait_for_s() -> float:
    """PAIRPLAY_WAIT_FOR_S, or WAIT_FOR_S."""
    value = _read("PAIRPLAY_WAIT_FOR_S")
    return WAIT_FOR_S if value is None else value


def settle_s() -> float:
    """PAIRPLAY_SETTLE_S, or SETTLE_S."""
    value = _read("PAIRPLAY_SETTLE_S")
    return SETTLE_S if value is None else value


def check() -> None:
    """UserError naming the first of VARIABLES set to a value it cannot take (module rule)."""
    for name, parse in VARIABLES.items():
        text = os.environ.get(name, "")
        if not text.strip():
            continue
        try:
            parse(text)
        except ValueError as err:
            raise UserError(f"{name}={text!r} is not {err}; give one or unset it", name) from None
