"""One session's web side: a bus service ("board") between the event log and the pages.

Rule: the hub keeps no truth. Its `BoardLogic` runs in a Node like every
service: it folds every event of the session into a `LabModel` (model.py) and
tells the pages to redraw. A page's input (a touch, the wrong-suggestion
button) becomes an event the hub publishes as source "board" (CardPicked,
WrongSuggestionPressed), stamped when the server took it (the server's
reaction-time clock) and carrying the page's own performance clock
(`page_time_ms`); the game decides what it means. A WebSocket message that
does not parse, comes from a read-only page, repeats or precedes an earlier
message of its page (`id` not increasing), or is about a turn or suggestion
that is no longer open (stale) is refused: the page is told why, and the
refusal is published as a MessageRejected, so the recording holds it.

Late input: a touch (or press) that reaches the hub more than LATE_MS after its
page made it is refused as late, not played (trial29 F7: a touch made just
before a Wi-Fi drop was held by the browser and played 25 s later, its timing
counted toward the ignore window). The page's heartbeat (common.js) stops
taking touches once a ping goes unanswered for its deadline; what the page
sent before it noticed may still arrive late, and this check drops it. Page and
server clocks are different machines' clocks, so lateness is not the difference
of two stamps: each message with the page's clock (`page_ms`: pings, touches)
gives `arrived - page_ms`, and a message's lateness is its value above the
smallest seen on that connection (the offset plus the fastest delivery; both
clocks run at one rate). The heartbeat's pings keep that smallest fresh.

A page's clock can jump (trial32 G): `performance.now()` does not tick while the
device sleeps (MDN "Ticking during sleep"), so a tablet whose screen was off for
10 s with its socket kept sends everything 10 s "later" than the smallest
offset, for ever. The baseline follows such a page: once its last REBASE_PINGS
pings agree on an offset (within AGREE_MS of each other) more than AGREE_MS
above the baseline, and were made at least SPAN_MS apart on the page's clock, their
smallest offset becomes the baseline. A held network cannot pass for that: what
it held arrives in one burst, so messages made SPAN_MS apart arrive with
offsets SPAN_MS apart, not within AGREE_MS; and a page's heartbeat sends at
most one ping into a socket that stopped answering before it abandons it
(common.js), so a held touch arrives with at most one held ping. A late refusal
tells the page (`"late": true`), which opens a new socket (a fresh baseline).

Pages: one "player" board per session acts; every other board page is
read-only ("viewer") until the player leaves, when the oldest viewer takes
over; a page that reloads keeps its `client` id (the browser tab's
sessionStorage) and so its role. A board connection with the id of one still
open is taken for that tab reloading (its old socket may not have closed yet):
the old one is closed with REPLACED. A page that gets REPLACED while alive is
not the reloaded tab but a twin that copied its sessionStorage (a duplicated
tab): it takes a fresh id and comes back once as another tab (common.js), so
two live tabs never evict each other in a loop. A mirror page is read-only. Every page gets
the whole view again on (re)connecting, so a page resumes from the server's
state. Publishing runs on the hub's own thread: neither a bus callback nor
the web server's event loop waits on a publish.
"""

from __future__ import annotations

import asyncio
import collections
import logging
import math
import queue
import secrets
import threading
import time
from typing import Callable, Union

import msgspec

from pairplay.core.geometry import N_CARDS
from pairplay.schemas import events as ev
from pairplay.schemas.events import EVENT_BY_TAG, Count, Int64, Seq
from pairplay.schemas.session import SessionConfig

from pairplay.services.bus import Bus
from pairplay.services.game import elsewhen
from pairplay.services.lab.model import LabModel
from pairplay.services.runner import Node
from pairplay.numbers import counted
from pairplay.schemas.nesting import JsonDecoder

log = logging.getLogger("pairplay.lab")
MAX_MESSAGE = 4096  # bytes: a page's messages are small; longer ones are refused and recorded
REPLACED = 4000  # WebSocket close code: a newer page came with this page's client id (see the module rule)
MAX_FRAME = 65536  # bytes: uvicorn closes the connection on a bigger frame (nothing to record but the close)
# ms: common.js's heartbeat deadline (DEADLINE_MS) plus its beat (BEAT_MS): a page that was still taking
# touches had heard from the server within this; a touch later than this was held by a network that was down
LATE_MS = 4000.0
# the baseline follows a page whose clock jumped (the module rule): its last REBASE_PINGS pings, made at least
# SPAN_MS apart on its clock (the heartbeat pings every second), agree within AGREE_MS (a lab network's and a loaded
# server's jitter is tens of ms; a held burst spreads its offsets by the time between the messages it held)
REBASE_PINGS = 3
SPAN_MS = 1500.0
AGREE_MS = 500.0


# -- what a page may send (JSON, tagged by "type") ----------------------------------------
# Every number a page sends is bounded here, where it enters (a message out of bounds is malformed, refused and
# recorded like any): the id as the bus's sequence numbers (`Seq`: it becomes a MessageRejected's offending_seq,
# and an id of 2**64 was taken as the page's last one, then refused by every peer in that rejection, and killed
# the lab's shutdown), round, turn and attempt as the events' counts; a card, whose
# refusal names the board's cards, as any 64-bit integer
class Pick(msgspec.Struct, tag="pick", forbid_unknown_fields=True):
    id: Seq  # the page's message counter: strictly increasing per page (client id)
    round: Count
    turn: Count
    card: Int64  # any card off the board is refused in words below
    page_ms: float  # performance.timeOrigin + performance.now() at the touch


class Wrong(msgspec.Struct, tag="wrong", forbid_unknown_fields=True):
    id: Seq
    round: Count
    turn: Count
    attempt: Count  # the suggestion the participant judged wrong
    page_ms: float


class Ping(msgspec.Struct, tag="ping", forbid_unknown_fields=True):
    t: float  # echoed back at once: the raw WebSocket round trip (bench), and the page's heartbeat (common.js)
    page_ms: Union[float, None] = None  # the page's clock when sent: the baseline of late input (module rule)


PageMessage = Union[Pick, Wrong, Ping]
_decode = JsonDecoder(PageMessage).decode
_encode = msgspec.json.Encoder().encode


class BoardLogic:
    """The hub's part on the bus: reads every event of the session, derives none."""

    name = "board"
    consumes = frozenset(EVENT_BY_TAG)
    sources: dict = {}

    def __init__(self, on_event: Callable[[ev.Event], None]):
        self.on_event = on_event
        self.done = False

    def start(self) -> list[ev.Event]:
        return []

    def handle(self, e: ev.Event) -> list[ev.Event]:
        self.on_event(e)
        if isinstance(e, ev.SessionEnded):
            self.done = True
        return []


class Client:
    def __init__(self, ws, page: str, client_id: str, role: str):
        self.ws, self.page, self.id, self.role = ws, page, client_id, role
        self.last_id = 0
        self.fastest_ms = float("inf")  # smallest (arrival - page_ms) on this connection (the module's late rule)
        self.pings: collections.deque = collections.deque(maxlen=REBASE_PINGS)  # (page_ms, offset) of the last pings
        self.outbox: asyncio.Queue = asyncio.Queue()
        self.state_pending = False
        self.sender: asyncio.Task | None = None


class LabHub:
    """The web side of one session (see the module rule)."""

    SEAT_KEPT_S = 3.0  # a reloading player's tab gets its seat back within this

    def __init__(self, config: SessionConfig, token: str | None = None, questionnaire: bool = False):
        self.config = config
        # a questionnaire follows this game (a study's game whose participant is asked one): the board asks for it
        # at the end only then; `pairplay lab` has none, and asking there logged a 404 in every game (trial27 F12)
        self.questionnaire = questionnaire
        self.session = config.session
        self.token = token or secrets.token_urlsafe(18)
        self.model = LabModel()
        self.lock = threading.Lock()  # the model: folded on bus threads, read on the event loop
        self.logic = BoardLogic(self._on_event)
        self.node: Node | None = None
        self.clients: list[Client] = []  # in order of arrival (the oldest viewer takes over)
        self.loop: asyncio.AbstractEventLoop | None = None
        self.rejections = 0
        self._seat: tuple[str, float] | None = None  # (client id, until): a leaving player's seat
        self._out: queue.Queue = queue.Queue()
        self._publisher = threading.Thread(target=self._publish_loop, name=f"pairplay-lab-{self.session}",
                                           daemon=True)
        self._publisher.start()

    # -- the bus side -------------------------------------------------------------------
    def make_node(self, bus: Bus) -> Node:
        """The hub's Node on `bus` (run_session starts it with the other services)."""
        self.node = Node(bus, self.logic, self.session)
        return self.node

    def _on_event(self, e: ev.Event) -> None:
        with self.lock:
            self.model.apply(e)
        loop = self.loop
        if loop is not None and not loop.is_closed():
            try:
                loop.call_soon_threadsafe(self._redraw_all)
            except RuntimeError:  # the loop closed in between (server stopping)
                pass

    def _publish_loop(self) -> None:
        while True:
            events = self._out.get()
            if events is None:
                return
            try:
                self.node.publish(events)
            except Exception:  # the bus is closing: nothing more can be recorded
                log.exception("lab %s: publish failed", self.session)

    def close(self, timeout_s: float = 5.0) -> None:
        """Stop the publishing thread after what it holds (waiting at most `timeout_s`)."""
        self._out.put(None)
        self._publisher.join(timeout_s)

    def token_ok(self, token: str) -> bool:
        return secrets.compare_digest(str(token).encode(), self.token.encode())

    # -- the pages ----------------------------------------------------------------------
    def view(self, client: Client) -> dict:
        with self.lock:
            view = self.model.mirror_view() if client.page == "mirror" else self.model.board_view()
        view["questionnaire"] = self.questionnaire
        return {"type": "state", "role": client.role, "state": view}

    def _redraw_all(self) -> None:
        for c in self.clients:
            self._redraw(c)

    def _redraw(self, c: Client) -> None:
        if not c.state_pending:
            c.state_pending = True
            c.outbox.put_nowait(None)  # None: the latest view, computed when it is sent

    async def _send_loop(self, c: Client) -> None:
        try:
            while True:
                item = await c.outbox.get()
                if item is None:
                    c.state_pending = False
                    item = self.view(c)
                await c.ws.send_text(_encode(item).decode())
        except asyncio.CancelledError:
            raise
        except Exception as err:  # the page went away mid-send: its receive loop ends the client
            log.info("lab %s: a %s page stopped listening: %s", self.session, c.page, err)

    def _role_for(self, page: str, client_id: str) -> str:
        if page != "board":
            return "mirror"
        if any(c.role == "player" for c in self.clients):
            return "viewer"
        if self._seat is not None and self._seat[0] != client_id and time.monotonic() < self._seat[1]:
            return "viewer"  # the player's tab is reloading: its seat is kept for a moment
        self._seat = None
        return "player"

    def _promote(self) -> None:
        """The player left and did not come back: the oldest read-only board takes over."""
        if any(c.role == "player" for c in self.clients):
            return
        if self._seat is not None and time.monotonic() < self._seat[1]:
            return
        self._seat = None
        viewer = next((v for v in self.clients if v.page == "board"), None)
        if viewer is not None:
            viewer.role = "player"
            self._redraw(viewer)

    async def serve(self, ws, page: str, client_id: str) -> None:
        """Talk to one accepted page until it goes away."""
        self.loop = asyncio.get_running_loop()
        if page == "board":
            # a reload: the same tab's old connection may not have closed yet; the tab keeps its role
            for old in [c for c in self.clients if c.id == client_id and c.page == "board"]:
                await self._drop(old, close=True)
        role = self._role_for(page, client_id)
        c = Client(ws, page, client_id, role)
        self.clients.append(c)
        c.sender = asyncio.create_task(self._send_loop(c))
        self._redraw(c)
        try:
            while True:
                message = await ws.receive()
                if message["type"] == "websocket.disconnect":
                    break
                text = message.get("text")
                if text is None:
                    raw = message.get("bytes") or b""
                    self._refuse(c, "binary frame: a page sends JSON text", raw)
                    continue
                self._take(c, text)
        finally:
            await self._drop(c)

    async def _drop(self, c: Client, close: bool = False) -> None:
        if c not in self.clients:
            return
        self.clients.remove(c)
        if c.sender is not None:
            c.sender.cancel()
        if close:
            try:
                await c.ws.close(code=REPLACED)
            except Exception:  # already gone
                pass
        if c.role == "player":  # keep the seat for a reload, then the oldest read-only board takes over
            self._seat = (c.id, time.monotonic() + self.SEAT_KEPT_S)
            asyncio.get_running_loop().call_later(self.SEAT_KEPT_S + 0.01, self._promote)

    # -- a page's input -----------------------------------------------------------------
    def _take(self, c: Client, text: str) -> None:
        raw = text.encode()
        if len(raw) > MAX_MESSAGE:
            self._refuse(c, f"message of {counted(len(raw), 'byte')}: a page's messages are at most {MAX_MESSAGE}", raw)
            return
        try:
            msg = _decode(raw)
        except (msgspec.DecodeError, msgspec.ValidationError) as err:
            self._refuse(c, f"malformed message: {err}", raw)
            return
        late_ms = self._lateness(c, msg.page_ms, isinstance(msg, Ping)) if msg.page_ms is not None else 0.0
        if isinstance(msg, Ping):
            c.outbox.put_nowait({"type": "pong", "t": msg.t, "server_ns": time.time_ns()})  # server clock: offset
            return
        if c.role != "player":
            self._refuse(c, f"a {c.role} page is read-only", raw, msg.id)
            return
        if msg.id <= c.last_id:
            self._refuse(c, f"message id {msg.id} is not above the page's last one ({c.last_id}): stale or repeated",
                         raw, msg.id)
            return
        c.last_id = msg.id
        with self.lock:
            m = self.model
            phase, here = m.phase(), (m.round, m.turn)
            open_attempt = m.suggestion["attempt"] if m.suggestion else -1
        if phase in ("starting", "over"):
            self._refuse(c, f"the game takes no input now ({phase})", raw, msg.id)
            return
        if (msg.round, msg.turn) != here:
            self._refuse(c, f"stale: {elsewhen((msg.round, msg.turn), here)}", raw, msg.id)  # counted from 1
            return
        if isinstance(msg, Pick):
            if not 0 <= msg.card < N_CARDS:
                self._refuse(c, f"card {msg.card} is not on the board (0..{N_CARDS - 1})", raw, msg.id)
                return
            event = ev.CardPicked(round=msg.round, turn=msg.turn, card=msg.card, page_time_ms=msg.page_ms)
        else:
            if phase != "second" or msg.attempt != open_attempt:
                self._refuse(c, f"stale: 'wrong suggestion' for attempt {msg.attempt}, but the open suggestion is "
                                f"{open_attempt if open_attempt >= 0 else 'none'}", raw, msg.id)
                return
            event = ev.WrongSuggestionPressed(round=msg.round, turn=msg.turn, attempt=msg.attempt,
                                              page_time_ms=msg.page_ms)
        if late_ms > LATE_MS:  # checked last: a message wrong in any other way says that first
            self._refuse(c, f"late: made {late_ms / 1000:.1f} s before it arrived (more than {LATE_MS / 1000:g} s: the "
                            "network held it while the page was cut off, or the page's clock stopped)", raw, msg.id,
                         late=True)  # the page opens a new socket (common.js): a fresh baseline
            return
        # stamped now: the envelope's time_ns is the server's clock of the touch
        self._out.put(self.node.stamp([event]))

    def _lateness(self, c: Client, page_ms: float, ping: bool) -> float:
        """How much later than its connection's baseline this message arrived, in ms (the module's rule)."""
        if not math.isfinite(page_ms):  # JSON's 1e999: no clock; it must not become everyone's baseline
            return 0.0
        offset = time.monotonic_ns() / 1e6 - page_ms
        c.fastest_ms = min(c.fastest_ms, offset)
        if ping:
            c.pings.append((page_ms, offset))
            self._rebase(c)
        return offset - c.fastest_ms

    def _rebase(self, c: Client) -> None:
        """The baseline follows the page's clock if its last pings agree on a larger offset (the module's rule)."""
        if len(c.pings) < REBASE_PINGS:
            return
        made = [p for p, _ in c.pings]
        offsets = [o for _, o in c.pings]
        if max(made) - min(made) < SPAN_MS or max(offsets) - min(offsets) > AGREE_MS:
            return  # too close together on the page's clock to tell from a burst, or not agreeing: held or jittery
        jump = min(offsets) - c.fastest_ms
        if jump > AGREE_MS:  # jitter within AGREE_MS is no jump: the baseline stays the fastest
            c.fastest_ms = min(offsets)
            log.info("lab %s: a %s page's clock jumped %.1f s (slept?): its late baseline follows", self.session,
                     c.page, jump / 1000)

    def _refuse(self, c: Client, reason: str, raw: bytes, msg_id: int = 0, late: bool = False) -> None:
        self.rejections += 1
        told = {"type": "rejected", "reason": reason, "id": msg_id}
        if late:
            told["late"] = True
        c.outbox.put_nowait(told)
        self.record_refusal(reason, f"ws/{self.session}/{c.page}", f"page:{c.id}", msg_id, raw)

    def record_refusal(self, reason: str, where: str, who: str = "", seq: int = 0, raw: bytes = b"") -> None:
        """Publish a MessageRejected for something a page or a connection attempt sent."""
        if self.node is not None:
            self._out.put(self.node.refuse(reason, where, who, seq, raw))
