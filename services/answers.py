"""Answers to a question put to one of a session's sources (`.../_query/<source>/...`), taken only as far as
the sessions that answered agree.

Rule: anyone the bus lets declare a queryable on a source's question can answer it (trial34 O: under an access
control that restricted only puts, the robot host answered the recorder's catch-up as the learner, and the
recorder wrote its forged learner event). Keeping other hosts off a source's questions is access control's job
(docs/examples/zenoh-tls-server.json5: `declare_queryable` and `reply` per source); this is the defence behind it:

- Each reply is kept with the session that sent it (Zenoh's `Reply.replier_id`, `Bus.query_replies`). Whether
  that session is the source's own cannot be checked: a liveliness reply carries no replier (zenoh-python 1.10:
  `replier_id` None) and a live sample no publisher unless the publisher sets it itself (`source_info`, its own
  claim), so pairplay has no source's session to compare with.
- An event (source, seq) is taken only if every session that gave it gave the same bytes; two that differ are a
  `Conflict`: neither is taken, both are named (the recorder records a MessageRejected; the seq stays a hole,
  which the file says, and no later answer fills it: `Recorder._undisputed`).
- An answer with nothing in it gives nothing and contradicts nothing: it never outvotes another session's events
  (the addendum: a forger's empty answer made a restarted recorder refuse its own live session).
- A question to the recorder (its log, what it holds) is answered by one recorder: answers of several sessions
  that differ are taken as no answer, said in a warning naming them (`one_answer`).

What this does not do: a forger that answers first and alone (the source slow, or gone before it is asked), or
with the very bytes the source sent (it listened), is taken. Only access control keeps it off the bus."""

from __future__ import annotations

import logging
from typing import Callable, NamedTuple

import msgspec

from pairplay.schemas.nesting import JsonDecoder, msgpack_decode

log = logging.getLogger("pairplay.answers")


class Stamp(msgspec.Struct):
    """What is needed of an event to pair it with another's: its source and seq (a full decode cost 6x, in a
    flood)."""
    source: str
    seq: int


stamp_of = JsonDecoder(Stamp).decode


class Conflict(NamedTuple):
    """Two sessions answered with different events for one (source, seq)."""
    source: str
    seq: int
    key: str
    data: bytes
    replier: str
    other_key: str
    other_data: bytes
    other: str

    def said(self) -> str:
        return (f"forged answer: two sessions answered with different events for {self.source} seq {self.seq} "
                f"({self.key} from {self.replier}, {self.other_key} from {self.other}); one of them is not "
                f"{self.source}'s: neither taken")


class Sent(NamedTuple):
    """What the answers to a `sent` question (services/runner.py SENT_QUERY) give: `answered`, the sources that
    answered; `events`, (key, payload) in the order they came, one per (source, seq), only those every session
    that gave them agrees on; `conflicts`, the (source, seq) they do not; `replies`, each reply read:
    (replier, the source it answers as: its reply key's when given, else its own word, its items)."""
    answered: list[str]
    events: list[tuple[str, bytes]]
    conflicts: list[Conflict]
    replies: list[tuple[str, str, list[tuple[str, bytes]]]]


def answering_as(reply_key: str) -> str | None:
    """The source a reply sent on `reply_key` (`pairplay/<session>/_query/<source>/<question>`) speaks for; None
    for a key of no such shape."""
    parts = reply_key.split("/")
    return parts[3] if len(parts) == 5 and parts[0] == "pairplay" and parts[2] == "_query" and parts[3] else None


def sent_answers(replies: list[tuple], unreadable: Callable[[str], None] | None = None,
                 foreign: Callable[[str, str, bytes, str, int], None] | None = None) -> Sent:
    """The answers (replier, payload, reply key) to a `sent` question (`Bus.query_replies(with_key=True)`) read
    and paired (see the rule). An item that does not decode is left out (the recorder's checks would refuse it);
    an unreadable reply is passed to `unreadable`. An item of another source than the one its reply was sent as
    (the reply's key, which access control limits per host: a robot host answering its own question with the
    learner's events, trial35 O1) is never taken: passed to `foreign(why, key, data, source, seq)` to record."""
    read: list[tuple[str, str, list[tuple[str, bytes]]]] = []
    for reply in replies:
        replier, payload = reply[0], reply[1]
        try:
            name, items = msgpack_decode(payload, type=tuple[str, list[tuple[str, bytes]]])
        except msgspec.DecodeError as err:
            if unreadable is not None:
                unreadable(f"{err} (from {replier})")
            continue
        read.append((replier, (answering_as(reply[2]) or "") if len(reply) > 2 else name, items))
    first: dict[tuple[str, int], tuple[str, bytes, str]] = {}  # (source, seq): (key, data, replier) first given
    order: list[tuple[str, int]] = []
    conflicts: dict[tuple[str, int], Conflict] = {}
    for replier, as_source, items in read:
        for key, data in items:
            try:
                stamp = stamp_of(data)
            except (msgspec.DecodeError, msgspec.ValidationError):
                continue
            key_source = key.split("/")[2] if key.count("/") >= 3 else ""
            if stamp.source != as_source or key_source != as_source:
                if foreign is not None:
                    foreign(f"forged answer: {replier or 'a session'} answered as {as_source!r} with "
                            f"{stamp.source!r}'s seq {stamp.seq} on {key}: not taken", key, data, stamp.source,
                            stamp.seq)
                continue
            at = (stamp.source, stamp.seq)
            if at not in first:
                first[at] = (key, data, replier)
                order.append(at)
            elif first[at][1] != data and at not in conflicts:
                k, d, r = first[at]
                conflicts[at] = Conflict(stamp.source, stamp.seq, k, d, r, key, data, replier)
    return Sent(answered=sorted({as_source for _, as_source, _ in read if as_source}),
                events=[first[at][:2] for at in order if at not in conflicts],
                conflicts=list(conflicts.values()), replies=read)


def one_answer(replies: list[tuple[str, bytes]], what: str) -> list[bytes]:
    """The payloads of the one session that answered a question to the recorder (`what`, for the warning), in
    the order they came; [] (no answer) if several sessions answered differently: one of them is not the
    recorder, and which cannot be told (see the rule)."""
    by: dict[str, list[bytes]] = {}
    for replier, payload in replies:
        by.setdefault(replier, []).append(payload)
    if len({tuple(sorted(p)) for p in by.values()}) > 1:
        log.warning("%s: %d sessions answered as the recorder, differently (%s); one of them is not the recorder: "
                    "no answer taken", what, len(by), ", ".join(sorted(by)))
        return []
    return next(iter(by.values()), [])
