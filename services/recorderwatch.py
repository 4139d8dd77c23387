"""Whether a session's external recorder is on the bus: the game is held while it is not.

Rule (docs/bus.md "A restarted recorder continues the record"): a game whose recorder is another process
(`pairplay session --external recorder`, `pairplay run game --wait-for recorder`) plays a round only while
that recorder's liveliness token is on the bus. Its token gone (a crash, a SIGTERM, a cut link), the watch
says so at once, one warning naming the round and how to restart it, and the game takes no input until a
recorder is back (`held`, Node.hold): a restarted recorder refills what it missed from the services' `sent`
while they are still on the bus. Not back within the settle time, the session ends "failed" and `lost()`
names the rounds that are in no recording. Before, the session played its remaining rounds unrecorded and
exited 0 saying "the external recorder writes its file" (trial33 K: 148 of 300 rounds nowhere).
The token callback runs on Zenoh's thread and only notes times.
"""

from __future__ import annotations

import threading
import time
from typing import Callable

from pairplay.errors import command_word
from pairplay.schemas.keys import alive_key
from pairplay.services.runner import GAME_GONE_S


RECHECK_S = 1.0  # while held, how often the bus is asked whether the recorder's token is back (`held`)


class RecorderWatch:
    """`settle_s`: how long the game waits for a recorder to come back (the session's settle time, `pairplay run game
    --settle`), said in its lines: the caller ends the session once `gone_for()` passes it."""

    def __init__(self, bus, session: str, round_now: Callable[[], int], connect: str = "", clock=time.monotonic,
                 settle_s: float = GAME_GONE_S, over: Callable[[], bool] = lambda: False):
        # `over()`: the game has ended. A recorder that leaves then holds no game back (nothing is left to
        # hold); whether it took the services' last events is asked of it at their end (services/recorded.py),
        # and its absence said there. Before, its drop said "at round 21 of 20: the game is held" (trial34 A).
        self.session, self.round_now, self.connect, self.clock, self.over = session, round_now, connect, clock, over
        self.settle_s = settle_s
        self._lock = threading.Lock()
        self.seen = False
        self.gone_since: float | None = None
        self.left_round: int | None = None  # the round (from 1) it left at, until a recorder is back
        self._said: list[str] = []  # what to say once (`line`)
        self.bus, self._recheck_at = bus, 0.0
        bus.watch_alive(alive_key(session, "recorder"), self._on_token)

    def _on_token(self, _key: str, up: bool) -> None:
        with self._lock:
            if up:
                if self.gone_since is not None:
                    self._said.append(f"a recorder is back on the bus (it refills what it missed from round "
                                      f"{self.left_round}); the game goes on")
                self.seen, self.gone_since, self.left_round = True, None, None
            elif self.seen and self.gone_since is None and not self.over():
                self.gone_since, self.left_round = self.clock(), self.round_now() + 1
                self._said.append(f"the recorder left the bus at round {self.left_round}: the game is held until one "
                                  f"is back (up to {self.settle_s:g} s); restart it (`pairplay run recorder --session {command_word(self.session)} "
                                  f"--connect {command_word(self.connect or 'ENDPOINT')}`) to refill what it missed")

    def held(self) -> bool:
        """True while the recorder that was on the bus is gone: the game takes no input (Node.hold). While it is,
        the bus is asked every RECHECK_S whether the token is back: after a cut of the recorder host's link the
        token's return reached no watcher, and the game stayed held for good (tests/test_netns.py, 180 s)."""
        if self.gone_since is None:
            return False
        now = self.clock()
        if now >= self._recheck_at:
            self._recheck_at = now + RECHECK_S
            key = alive_key(self.session, "recorder")
            if key in self.bus.alive_now(key, timeout_s=0.3):
                self._on_token(key, True)
        return self.gone_since is not None

    def gone_for(self) -> float:
        """Seconds since the recorder left the bus (0 while one is on it)."""
        since = self.gone_since
        return 0.0 if since is None else self.clock() - since

    def line(self) -> str:
        """What happened since the last call, to say as a warning ("" if nothing)."""
        with self._lock:
            said, self._said = "; ".join(self._said), []
        return said

    def lost(self, last_round: int, signal: str = "") -> str:
        """If the recorder is gone now: which rounds no recording holds (`last_round`: the game's last, from 1).
        `signal`: the signal that stopped the session while it was held ("SIGINT"), said instead of "none came
        back within 30 s", which read as the settle time having passed (trial34 H)."""
        if self.left_round is None:
            return ""
        first = self.left_round
        rounds = f"round {first}" if first >= last_round else f"rounds {first}..{last_round}"
        if signal:
            return (f"interrupted ({signal}) while held for the recorder (it left the bus at round {first}): {rounds} "
                    f"not recorded (session {self.session})")
        return (f"the recorder left the bus at round {first} and none came back within {self.settle_s:g} s: {rounds} "
                f"not recorded "
                f"(session {self.session})")
