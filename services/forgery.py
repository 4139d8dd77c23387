"""What a session does when its game sees a forged SessionStarted or SessionEnded (issue "forge").

Rule: Zenoh names no publisher per message (docs/bus.md "Security"), so another process on the
bus can publish a start or an end claiming source "game". The game gets every message on its own
keys and names one it did not publish (services/guard.py `forged`). Every listener refuses a start
or end that does not fit the game's sequence (guard.py); one that fits is taken. The session then:
- plays on when the forgery was refused everywhere it can tell: no listener in this process took
  it (their guards' `took_message`: the learner, the participant, the robot bridge, the lab's board,
  the recorder; that message, by its bytes, not whatever they took at its key and seq: a replayed
  old recording's start, at the seq of the game's own, is refused by all), and no consumer of the event runs in another process, or its seq lies more than
  MAX_SEQ_JUMP above what the game had published (every guard refuses that jump);
  the forgery stays in the file as the game's refusal (a MessageRejected "forged: ...");
- stops otherwise (`verdict` names why), within the 0.1 s the session's watch loop checks it
  (services/session.py watch_services): a listener that took a forged end has stopped, one that
  took a forged start plays another config, and a listener in another process cannot be asked.
  The game ends the session "failed" with the forgery as its detail, the recording is finished,
  and `pairplay session` exits non-zero with one line naming the event, its claimed source and
  that this game did not publish it (session.ForgedEvent).
The check runs in the session's watch loop, never on the hot path: the game pays one dict insert
per event it publishes and one lookup per echo (services/runner.py `Node.publish`).
"""

from __future__ import annotations

from pairplay.schemas.catalogue import FLOW
from pairplay.schemas.keys import event_key
from pairplay.schemas.trust import MAX_SEQ_JUMP, ONCE_PER_SESSION

EVERYTHING = ("recorder", "board")  # listeners that take every event of the session (schemas/catalogue.py FLOW)
# every service that may act on a start or an end: a game alone in its process (`pairplay run game`) has them all elsewhere
EVERY_LISTENER = tuple(sorted({s for tag in ONCE_PER_SESSION for s in FLOW[tag][1]} | set(EVERYTHING)))


def consumers(tag: str) -> tuple[str, ...]:
    """The services that act on `tag` (FLOW's consumers and those that take every event)."""
    return FLOW.get(tag, ((), ()))[1] + EVERYTHING


class ForgeryWatch:
    """The session's view of the forgeries its game saw (see rule). `game`: the game's Node;
    `listeners`: (name, guard) of every other in-process listener and the recorder; `external`:
    the names of the services the session needs that run in other processes."""

    def __init__(self, game, listeners, external=()):
        self.game, self.listeners, self.external = game, list(listeners), tuple(external)

    def verdict(self) -> str:
        """"" to play on; else why the session stops: the forgery named, and who took it or might have."""
        if self.game is None:
            return ""
        for event, reason, message in list(self.game.driver.guard.forged):
            tag = type(event).__name__ if event is not None else ""
            if tag not in ONCE_PER_SESSION:
                continue
            what = reason.removeprefix("forged: ")
            key = event_key(event.session, event.source, tag)
            # that very message, not its (key, seq): the listeners took the game's own start at that seq, and a
            # replayed old recording's copy of it, refused by all, was said taken and stopped the session (F14)
            took = [name for name, guard in self.listeners if guard.took_message(key, event.seq, message)]
            if took:
                return f"{what}; taken by {', '.join(took)}"
            elsewhere = [s for s in self.external if s in consumers(tag)]
            if elsewhere and event.seq <= self.game.driver.seq + MAX_SEQ_JUMP:
                return f"{what}; {', '.join(elsewhere)} in another process may have taken it"
        return ""
