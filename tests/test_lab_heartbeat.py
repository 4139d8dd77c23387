"""A lab page whose network drops without its socket closing (half-open TCP) knows it, says it, and drops touches.

Trial29 F7: with the network gone and the WebSocket left half-open (Chromium's offline emulation: Playwright's
`set_offline` plus CDP `Network.emulateNetworkConditions`), the board kept its prompt, took a touch, and the
touch was delivered and played ~25 s later, back online (its timing counted toward the ignore window). The
page's heartbeat (common.js) now marks the socket down when a ping goes unanswered past its deadline; the hub
refuses a touch that arrives later than its page's heartbeat allows (hub.py LATE_MS). Real headless Chromium,
a real lab session, and a real WebSocket client for the server's side.
"""

from __future__ import annotations

import json
import time

from websockets.sync.client import connect

from labutil import human_config, open_page, running_lab, wait_phase
from pairplay.replay.reader import read_log
from pairplay.services.lab.hub import AGREE_MS, LATE_MS, SPAN_MS

from test_lab_bounds import _reply

OFF = {"offline": True, "latency": 0, "downloadThroughput": -1, "uploadThroughput": -1}
ON = {"offline": False, "latency": 0, "downloadThroughput": -1, "uploadThroughput": -1}


def _network(page, cdp, up: bool) -> None:
    """The page's network up or down as a Wi-Fi drop leaves it: the open socket is not closed."""
    page.context.set_offline(not up)
    cdp.send("Network.emulateNetworkConditions", ON if up else OFF)


def test_a_board_whose_network_drops_says_reconnecting_drops_the_touch_and_comes_back(browser, tmp_path):
    config = human_config("lab-beat", rounds=1)
    with running_lab(tmp_path, config) as lab:
        page = open_page(browser, lab.urls.board)
        wait_phase(page, "first")
        page.wait_for_function("window.pairplay.canTouch()")
        cdp = page.context.new_cdp_session(page)
        _network(page, cdp, up=False)
        # the socket is not closed (half-open): only the heartbeat can tell
        page.wait_for_function("document.getElementById('prompt').textContent === 'Reconnecting…'", timeout=20000)
        assert page.evaluate("window.pairplay.link.lost") >= 1  # the heartbeat, not a close, found it
        assert not page.evaluate("window.pairplay.canTouch()")
        page.click("[data-card='4']")  # a touch while down: dropped, never sent, never waited for
        assert page.evaluate("window.pairplay.sent") == 0
        assert "pending" not in page.get_attribute("[data-card='4']", "class")
        _network(page, cdp, up=True)
        page.wait_for_function("window.pairplay.canTouch()", timeout=20000)
        assert page.inner_text("#prompt") == "Pick a card"
        state = page.evaluate("window.pairplay.state")
        assert state["phase"] == "first" and state["cards"][4]["state"] == "down"  # the touch was not played
        page.click("[data-card='2']")  # back: the next touch is taken
        wait_phase(page, "looking", "thinking", "second")
        assert page.errors == []
        lab.stop.set()
        path = lab.wait()
    picks = [r.event for r in read_log(path).events if type(r.event).__name__ == "CardPicked"]
    assert [p.card for p in picks] == [2]


def _ws_url(board_url: str, client: str) -> str:
    return board_url.replace("http://", "ws://").replace("/board?", "/ws?") + f"&page=board&client={client}"


def test_a_touch_that_arrives_later_than_the_heartbeat_allows_is_refused_and_recorded(tmp_path):
    """The page's heartbeat leaves a window (a touch sent just before the page noticed): a touch held by the
    network and delivered later than LATE_MS after its page's fastest message is refused as late, not played."""
    config = human_config("lab-late", rounds=1)
    with running_lab(tmp_path, config) as lab:
        with connect(_ws_url(lab.urls.board, "held"), open_timeout=30) as ws:
            while True:
                message = json.loads(ws.recv(timeout=60))
                if message["type"] == "state" and message["state"]["phase"] == "first":
                    break
            page_ms = time.time() * 1000  # this client's page clock
            ws.send(json.dumps({"type": "ping", "t": 1.0, "page_ms": page_ms}))
            assert _reply(ws)["type"] == "pong"
            # a touch made 3 heartbeat deadlines ago on the page's clock, arriving now: the network held it
            ws.send(json.dumps({"type": "pick", "id": 1, "round": 0, "turn": 0, "card": 3,
                                "page_ms": page_ms - 3 * LATE_MS}))
            refused = _reply(ws)
            assert refused["type"] == "rejected" and refused["reason"].startswith("late: "), refused
            assert refused.get("late") is True  # the page is told it was late: it opens a new socket (common.js)
            # a fresh touch is taken
            ws.send(json.dumps({"type": "pick", "id": 2, "round": 0, "turn": 0, "card": 5,
                                "page_ms": time.time() * 1000}))
            while True:
                message = json.loads(ws.recv(timeout=60))
                assert message["type"] != "rejected", message
                if message["type"] == "state" and message["state"]["first"] == 5:
                    break
        lab.stop.set()
        path = lab.wait()
    events = [r.event for r in read_log(path).events]
    assert [e.card for e in events if type(e).__name__ == "CardPicked"] == [5]
    late = [e for e in events if type(e).__name__ == "MessageRejected" and e.reason.startswith("late: ")]
    assert len(late) == 1 and late[0].key == "ws/lab-late/board"


def _first_turn(ws) -> None:
    while True:
        message = json.loads(ws.recv(timeout=60))
        if message["type"] == "state" and message["state"]["phase"] == "first":
            return


def _ping(ws, page_ms: float) -> None:
    ws.send(json.dumps({"type": "ping", "t": page_ms, "page_ms": page_ms}))
    assert _reply(ws)["type"] == "pong"


def _pick_taken(ws, msg_id: int, card: int, page_ms: float) -> None:
    """The pick is played (the view's first card), not refused."""
    ws.send(json.dumps({"type": "pick", "id": msg_id, "round": 0, "turn": 0, "card": card, "page_ms": page_ms}))
    while True:
        message = json.loads(ws.recv(timeout=60))
        assert message["type"] != "rejected", message
        if message["type"] == "state" and message["state"]["first"] == card:
            return


def test_a_page_whose_clock_stopped_while_it_slept_plays_on_once_its_pings_agree(tmp_path):
    """Trial32 G: performance.now() does not tick while a device sleeps, so a tablet whose screen was off 10 s
    (its socket kept) sends page_ms 10 s behind from then on. Its fresh pings, a heartbeat apart, agree on the
    new offset: the baseline follows them, and its next touch is played, not refused as late for ever."""
    config = human_config("lab-slept", rounds=1)
    with running_lab(tmp_path, config) as lab:
        with connect(_ws_url(lab.urls.board, "slept"), open_timeout=30) as ws:
            _first_turn(ws)
            slept_ms = 0.0
            clock = lambda: time.time() * 1000 - slept_ms  # noqa: E731 (the page's clock: stops while asleep)
            for _ in range(3):  # the heartbeat, awake
                _ping(ws, clock())
                time.sleep(1.0)
            slept_ms = 10_000.0  # the device slept 10 s: the page's clock did not move meanwhile
            for beat in range(3):  # awake again: the heartbeat's next three pings, a second apart
                _ping(ws, clock())
                if beat < 2:
                    time.sleep(1.0)
            _pick_taken(ws, 1, 3, clock())
        lab.stop.set()
        path = lab.wait()
    events = [r.event for r in read_log(path).events]
    assert [e.card for e in events if type(e).__name__ == "CardPicked"] == [3]
    assert not [e for e in events if type(e).__name__ == "MessageRejected"]


def test_pings_held_with_a_touch_do_not_move_the_baseline(tmp_path):
    """The heartbeat's purpose holds: what a network held arrives in one burst, so pings it held (made a second
    apart, or close together) do not agree on a new offset the way a slept clock's fresh pings do, and the touch
    held with them is refused as late."""
    config = human_config("lab-burst", rounds=1)
    with running_lab(tmp_path, config) as lab:
        with connect(_ws_url(lab.urls.board, "held"), open_timeout=30) as ws:
            _first_turn(ws)
            now = lambda: time.time() * 1000  # noqa: E731
            _ping(ws, now())
            made = now() - 10_000.0  # the network went down 10 s ago; all this was held, and arrives now
            for i in range(3):  # a heartbeat a second apart (more than the one the page sends before it gives up)
                ws.send(json.dumps({"type": "ping", "t": 1.0 + i, "page_ms": made + 1000.0 * i}))
            for i in range(3):  # or close together (the bench's pings): agreeing, but not spread over SPAN_MS
                ws.send(json.dumps({"type": "ping", "t": 10.0 + i, "page_ms": made + 3000.0 + 100.0 * i}))
            assert 2 * 100.0 < SPAN_MS and 1000.0 > AGREE_MS  # what the two bursts stand for
            ws.send(json.dumps({"type": "pick", "id": 1, "round": 0, "turn": 0, "card": 3,
                                "page_ms": made + 3500.0}))
            refused = _reply(ws)
            while refused["type"] == "pong":
                refused = _reply(ws)
            assert refused["type"] == "rejected" and refused.get("late") is True, refused
            _pick_taken(ws, 2, 5, now())  # the page's fresh touch (it went on at the old baseline) is played
        lab.stop.set()
        path = lab.wait()
    events = [r.event for r in read_log(path).events]
    assert [e.card for e in events if type(e).__name__ == "CardPicked"] == [5]


# The page's side of trial32 G, in real headless Chromium. A device's sleep is modelled from the page's view: the
# wall clock (Date.now) goes on while performance.now() stands still (Chromium cannot sleep a page's clock). The
# page's events around it are dispatched by hand: headless Chromium fires none of them (CDP's
# Page.setWebLifecycleState, a minimized window or a tab brought over it left the page visible and unfrozen).
SLEEP = """([away, back]) => {
    const target = ["pagehide", "pageshow"].includes(away) ? window : document;
    const hidden = (on) => {
        Object.defineProperty(document, "hidden", {configurable: true, get: () => on});
        Object.defineProperty(document, "visibilityState", {configurable: true, get: () => on ? "hidden" : "visible"});
    };
    if (away) { if (away === "visibilitychange") hidden(true); target.dispatchEvent(new Event(away)); }
    const before = Date.now.bind(Date);  // a page that slept before: its 10 s stay
    Date.now = () => before() + 10000;  // 10 s asleep: the wall clock went on, the page's clock did not
    if (back) { if (back === "visibilitychange") hidden(false); target.dispatchEvent(new Event(back)); }
}"""
WAKES = [("visibilitychange", "visibilitychange"), ("freeze", "resume"), ("pagehide", "pageshow")]


def _renewed(page, times: int, why: str) -> None:
    """The page replaced its live socket `times` times so far, the last for `why`, is connected again and still
    the player."""
    page.wait_for_function(f"(window.pairplay.link.renewed || []).length === {times} && "
                           f"window.pairplay.link.renewed[{times - 1}] === {why!r} && "
                           f"window.pairplay.link.connects === {times + 1} && window.pairplay.canTouch()",
                           timeout=15000)
    assert page.evaluate("window.pairplay.role") == "player"  # the hub took the new socket as this tab's: its seat
    assert page.evaluate("window.pairplay.link.lost") == 0  # not the heartbeat's doing


def test_a_board_back_from_sleep_opens_a_new_socket_and_plays_on(browser, tmp_path):
    """Hidden, frozen or away (pagehide) while the device slept: back, the board opens a new socket (a fresh
    baseline for the hub's late rule) and keeps its seat; asleep while visible (no event at all), its heartbeat
    sees its clock fell behind the wall clock and does the same."""
    config = human_config("lab-woke", rounds=1)
    with running_lab(tmp_path, config) as lab:
        page = open_page(browser, lab.urls.board)
        wait_phase(page, "first")
        page.wait_for_function("window.pairplay.canTouch()")
        for n, (away, back) in enumerate(WAKES, start=1):
            page.evaluate(SLEEP, [away, back])
            _renewed(page, n, "woke")
        page.evaluate(SLEEP, [None, None])  # asleep while visible
        _renewed(page, len(WAKES) + 1, "slept")
        page.click("[data-card='2']")
        wait_phase(page, "looking", "thinking", "second")
        assert page.errors == []
        lab.stop.set()
        path = lab.wait()
    events = [r.event for r in read_log(path).events]
    assert [e.card for e in events if type(e).__name__ == "CardPicked"] == [2]
    assert not [e for e in events if type(e).__name__ == "MessageRejected"]


def test_a_touch_refused_as_late_says_so_on_the_board_and_the_board_reconnects(browser, tmp_path):
    """The hub refuses a touch as late (here one whose page_ms is 20 s old): the board does not stay silent
    with a card that does not turn; it opens a new socket and asks for the touch again."""
    config = human_config("lab-again", rounds=1)
    with running_lab(tmp_path, config) as lab:
        page = open_page(browser, lab.urls.board)
        wait_phase(page, "first")
        page.wait_for_function("window.pairplay.canTouch()")
        page.evaluate("""() => { const p = window.pairplay, s = p.state;
            p.link.send({type: "pick", id: p.nextId(), round: s.round, turn: s.turn, card: 4,
                         page_ms: window.pairplayLab.now() - 20000}); }""")
        _renewed(page, 1, "late")
        assert page.inner_text("#prompt") == "That touch came too late: please touch again"
        page.click("[data-card='4']")
        wait_phase(page, "looking", "thinking", "second")
        assert page.inner_text("#prompt") != "That touch came too late: please touch again"
        assert page.errors == []
        lab.stop.set()
        path = lab.wait()
    events = [r.event for r in read_log(path).events]
    assert [e.card for e in events if type(e).__name__ == "CardPicked"] == [4]
    late = [e for e in events if type(e).__name__ == "MessageRejected" and e.reason.startswith("late: ")]
    assert len(late) == 1  # recorded as every refusal is
