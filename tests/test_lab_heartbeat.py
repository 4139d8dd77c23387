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
from pairplay.services.lab.hub import LATE_MS

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
