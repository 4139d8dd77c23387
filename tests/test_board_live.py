"""The board page under real use (trial27), in a real headless Chromium, one lab session for the module.

Rules tested: a touch (or the wrong-suggestion button) while the page's WebSocket is down is dropped,
never left waiting for an answer that was never sent, and the board takes the next touch once it is
back; a tab duplicated with the same client id does not fight the first in a reconnect loop (the page
that loses its id to a live twin takes a fresh one and is read-only); the experimenter's pause shows
on the board at once, which then invites no touch, until the resume.
"""

from __future__ import annotations

import time

import pytest

from labutil import human_config, open_page, running_lab, wait_phase
from pairplay.schemas import events as ev
from pairplay.schemas.envelope import stamped
from pairplay.schemas.keys import event_key

SESSION = "lab-live"


@pytest.fixture(scope="module")
def lab(browser, tmp_path_factory):
    with running_lab(tmp_path_factory.mktemp("live"), human_config(SESSION, rounds=1)) as running:
        yield running


def offline_touch(page, card: int) -> dict:
    """Drop the page's WebSocket and touch `card` right after the page learns it (before the
    reconnect, which is a timer the touch precedes): what the page then holds."""
    return page.evaluate("""async (card) => {
        const ws = window.pairplay.link.ws;
        const closed = new Promise(r => ws.addEventListener("close", r));
        ws.close();
        await closed;  // the page's onclose ran: it reconnects on a timer
        const sent = window.pairplay.sent;
        document.querySelector(`[data-card='${card}']`).click();
        return {sent: window.pairplay.sent - sent, open: window.pairplay.link.open,
                cls: document.querySelector(`[data-card='${card}']`).className,
                prompt: document.getElementById("prompt").textContent};
    }""", card)


def test_a_touch_while_offline_is_dropped_and_the_board_goes_on(browser, lab):
    page = open_page(browser, lab.urls.board)
    wait_phase(page, "first")
    got = offline_touch(page, 2)
    assert got == {"sent": 0, "open": False, "cls": "card down", "prompt": "Reconnecting…"}, got
    # back: the board takes touches again (before the fix it waited for ever on card 2's answer)
    page.wait_for_function("window.pairplay.link.connects === 2 && window.pairplay.canTouch()", timeout=10000)
    page.click("[data-card='2']")
    wait_phase(page, "looking", "thinking", "second")
    assert page.evaluate("window.pairplay.state.first") == 2
    # the wrong-suggestion button pressed offline: dropped, and live again once back
    wait_phase(page, "second")
    pressed = page.evaluate("""async () => {
        const ws = window.pairplay.link.ws, closed = new Promise(r => ws.addEventListener("close", r));
        ws.close(); await closed;
        const wrong = document.getElementById("wrong");
        wrong.disabled = false;  // a press that raced the redraw
        wrong.click();
        return window.pairplay.link.open; }""")
    assert pressed is False
    page.wait_for_function("window.pairplay.link.connects === 3 && window.pairplay.link.up() && "
                           "!document.getElementById('wrong').disabled", timeout=10000)
    assert page.errors == []
    page.context.close()


def control(lab, event: ev.Event, seq: int) -> None:
    """The experimenter's console's message on the game's bus (as services/protocol.py `_control`)."""
    e = stamped(event, session=SESSION, source="experimenter", seq=seq, time_ns=time.time_ns())
    lab.bus.put(event_key(SESSION, "experimenter", type(event).__name__), ev.encode_event(e))


def test_the_experimenters_pause_shows_on_the_board_until_the_resume(browser, lab):
    page = open_page(browser, lab.urls.board)
    page.wait_for_function("window.pairplay.canTouch()", timeout=10000)
    control(lab, ev.SessionPaused(reason="a break"), 1)
    page.wait_for_function("window.pairplay.state.paused", timeout=10000)
    assert page.evaluate("window.pairplay.canTouch()") is False
    assert page.text_content("#prompt") == "The game is paused: please wait"
    assert page.evaluate("document.body.classList.contains('paused')")
    control(lab, ev.SessionResumed(), 2)
    page.wait_for_function("!window.pairplay.state.paused && window.pairplay.canTouch()", timeout=10000)
    assert page.text_content("#prompt") != "The game is paused: please wait"
    assert page.errors == []
    page.context.close()


def test_a_duplicated_tab_does_not_fight_the_first_in_a_reconnect_loop(browser, lab):
    first = open_page(browser, lab.urls.board)
    first.wait_for_function("window.pairplay.role === 'player'", timeout=10000)
    taken = first.evaluate("window.pairplayLab.client")
    # a duplicated tab: Chrome's "Duplicate tab" (and window.open) copies the tab's sessionStorage, its id too
    twin_ctx = browser.new_context(viewport={"width": 1024, "height": 600}, bypass_csp=True)
    twin_ctx.add_init_script(f"sessionStorage.setItem('pairplay-client', '{taken}')")
    twin = twin_ctx.new_page()
    twin_errors: list[str] = []
    twin.on("pageerror", lambda e: twin_errors.append(str(e)))
    twin.goto(lab.urls.board)
    # the first page lost its id to a live twin: it takes a fresh one and comes back once, read-only
    first.wait_for_function(f"window.pairplay.link.connects === 2 && window.pairplay.link.up() && "
                            f"window.pairplay.role === 'viewer' && window.pairplayLab.client !== '{taken}'",
                            timeout=10000)
    twin.wait_for_function("window.pairplay.state && window.pairplay.role === 'player'", timeout=10000)
    # both still connected after a round trip each: no page evicted the other again
    for page in (first, twin):
        page.evaluate("window.pairplay.link.ping()")
    assert [first.evaluate("window.pairplay.link.connects"), twin.evaluate("window.pairplay.link.connects")] == [2, 1]
    assert first.evaluate("sessionStorage.getItem('pairplay-client')") != taken  # a reload of it stays the other tab
    assert first.errors == [] and twin_errors == []
    first.context.close()
    twin_ctx.close()
