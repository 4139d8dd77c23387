"""What a session does when a service refuses the game's own SessionStarted or SessionEnded (task "refusal").

Rule: every service records what it refuses as a MessageRejected on its own key
(pairplay/<session>/<service>/MessageRejected: the recorder, the learner, the participant, the
robot bridge, the lab's board, a service in another process), naming the offending key and seq.
A service that refused the game's real start never plays (the learner never suggests, the
participant never picks) and one that refused its real end never ends: either way the session
waited for ever, or played on without it, and never said why (only the recorder's refusal of the
start was watched). So the session watches every service's MessageRejected and acts on a refusal
of the game's own start or end:
- "the game's own": the offending key is the game's SessionStarted/SessionEnded key, the
  offending seq is the one the game published there (its Outbox's `sent`), and the refusal's
  excerpt (the message's first bytes) is that of the game's message. A refusal of a forged start
  or end is not (services/forgery.py: another seq, or at the same seq other bytes: a replayed old
  recording's start at the seq of the game's own was refused by every listener, and the session
  was stopped as if they had refused the game's, trial28 F14; the game's own "forged: ..."
  refusals are the game's, not a listener's), nor a "contradicted: " notice (services/guard.py:
  it names the start or end the service took, turned out not to be the game's);
- a refused start stops the session at once: the game ends it "failed", naming the service and
  its reason, the recording is finished, and the verb exits non-zero with one line (StartRefused);
- a refused end: the game has ended the session; the session stops waiting for the service that
  will not end, finishes the recording and says so in one line (EndRefused).
The subscription's callback only decodes and keeps what names the game's start or end key (at
most KEPT, so a flood cannot grow it); the judgement runs in the session's watch loop every 0.1 s,
as the forgery watch's does (services/session.py watch_services), and only once the game has
published the event, so a refusal that overtook the game's own Outbox is judged all the same.
A game in a process of its own (`pairplay run game`) watches its start the same way; a session
whose game is elsewhere (`--external game`) leaves it to that game's process: only the game knows
which start is its own.
"""

from __future__ import annotations

import threading

from pairplay.errors import UserError
from pairplay.schemas.events import MessageRejected, decode_event, own_seq
from pairplay.schemas.keys import event_key, session_keys
from pairplay.services.guard import CONTRADICTED, excerpt

KEPT = 1000  # refusals naming the game's start or end key kept until judged; more are dropped unjudged
WHAT = {"SessionStarted": "start", "SessionEnded": "end"}


class StartRefused(UserError):
    """A service refused the game's SessionStarted (`reason`): it can take no part in the session (the
    recorder: nothing of it can be recorded; the learner: no suggestion comes). The session is ended at
    once instead of waiting for what cannot come (the new-user trial's 10-minute hang). `where`: the recording."""


class EndRefused(UserError):
    """A service refused the game's SessionEnded: it does not end with the session, so the session stops
    waiting for it and finishes the recording. `where`: the recording."""


def refused_text(tag: str, refusals: list[tuple[str, str]]) -> str:
    """The line of a session whose `tag` (SessionStarted/SessionEnded) was refused: who, and the first
    one's reason. A recorder that had taken another start on the game's key first took one that was not
    this game's (it publishes one start): say so."""
    who = ", ".join(dict.fromkeys(source for source, _ in refusals))
    source, reason = refusals[0]
    text = f"the {who} refused the session's {WHAT[tag]} ({reason[:200]})"
    if tag == "SessionStarted" and (reason.startswith("a second SessionStarted") or "duplicate or out of order" in reason):
        text += (f"; the SessionStarted the {source} took first claiming source 'game' was not this game's (another "
                 "process on the bus forged it, or the recording is an earlier session's)")
    if tag == "SessionEnded":  # the game has ended the session; what refused its end would not end with it
        return text + f"; the session did not wait for {'them' if ', ' in who else 'it'} to end"
    return text + "; the session was stopped"


def published_seq(node, tag: str, newest: bool | None = None) -> int | None:
    """The seq of a node's own `tag` event once its Outbox has published it (None before): the first,
    or with `newest` the last one (by default the game's end, near the end of what it sent; its start
    is near the beginning). Also the robot bridge's count of its in-process learner's suggestions."""
    payload = published(node, tag, newest)
    return None if payload is None else own_seq(payload)


def published(node, tag: str, newest: bool | None = None) -> bytes | None:
    """The payload of a node's own `tag` event once its Outbox has published it (None before), the first or
    the last as `published_seq` says."""
    key = event_key(node.session, node.logic.name, tag)
    newest = tag == "SessionEnded" if newest is None else newest
    for k, payload in (reversed(node.outbox.sent) if newest else node.outbox.sent):
        if k == key:
            return payload
    return None


class RefusalWatch:
    """The session's watch on refusals of its game's own start and end (see rule). `game`: the game's
    Node (its Outbox keeps what it sent); `tags`: which of its events the caller acts on."""

    def __init__(self, bus, session: str, game, tags: tuple[str, ...] = tuple(WHAT)):
        self.game, self.tags = game, tags
        self.keys = {event_key(session, "game", tag): tag for tag in tags}
        self.seqs: dict[str, int] = {}  # tag -> the seq the game published it with (published_seq)
        self.excerpts: dict[str, str] = {}  # tag -> the excerpt a refusal of the game's own gives (guard.excerpt)
        self.kept: list[tuple[str, int, str, str, str]] = []  # (tag, offending seq, service, reason, excerpt) to judge
        self.found: dict[str, list[tuple[str, str]]] = {}  # tag -> [(service, reason)] of the game's own refused
        self._lock = threading.Lock()  # Zenoh's threads append, the watch loop judges
        # every source's refusals (the Node's by-tag subscription's form: services/runner.py)
        self.subscriber = bus.subscribe(f"{session_keys(session)[:-2]}*/MessageRejected", self._seen)

    def _seen(self, _key: str, payload: bytes) -> None:
        """Zenoh's thread: keep a refusal naming the game's start or end key (never waits on a publish)."""
        try:
            e = decode_event(payload)
        except Exception:  # a malformed refusal is its publisher's; the recorder refuses and records it
            return
        tag = self.keys.get(e.key) if isinstance(e, MessageRejected) else None
        # the game's own refusals on its keys are of forgeries; a notice is not a refusal (see rule)
        if tag is None or e.source == "game" or e.reason.startswith(CONTRADICTED):
            return
        if self.seqs.get(tag, e.offending_seq) != e.offending_seq:
            return  # of another start or end than the game's, known by now: a flood of those keeps nothing
        with self._lock:
            if len(self.kept) < KEPT:
                self.kept.append((tag, e.offending_seq, e.source, e.reason, e.excerpt))

    def verdict(self) -> str:
        """"" to go on; else the line of the first of the game's own events a service refused."""
        if self.game is not None and self.kept:
            self._judge()
        for tag in self.tags:
            if tag in self.found:
                return refused_text(tag, self.found[tag])
        return ""

    def _judge(self) -> None:
        """Move the refusals kept so far into `found` (the game's own) or drop them (see rule)."""
        with self._lock:
            kept, self.kept = self.kept, []
        for tag, seq, source, reason, said in kept:
            real = self.seqs.get(tag)
            if real is None:
                # a game that has not ended has published no end: no scan of all it sent (a forged end's refusal)
                ended = tag != "SessionEnded" or self.game.logic.done
                payload = published(self.game, tag) if ended else None
                if payload is None:  # not published yet (the refusal overtook the game's Outbox): judged later
                    with self._lock:
                        self.kept.append((tag, seq, source, reason, said))
                    continue
                real = self.seqs[tag] = own_seq(payload)
                self.excerpts[tag] = excerpt(payload)
            # at the game's seq, and its bytes (a copy at that seq is not the game's: see rule); a refusal without
            # an excerpt cannot tell, and counts as of the game's own
            if seq == real and (not said or said == self.excerpts[tag]):
                self.found.setdefault(tag, []).append((source, reason))

    def error(self, where) -> UserError | None:
        """The error a verb raises for what `verdict` found (None if nothing)."""
        self.verdict()
        for tag, kind in (("SessionStarted", StartRefused), ("SessionEnded", EndRefused)):
            if tag in self.found:
                return kind(refused_text(tag, self.found[tag]), where)
        return None
