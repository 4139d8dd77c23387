"""The console page in a real headless Chromium: what it says of the board, and its layout at lab screen sizes.

A new user's trial (2026-12-01): the console said the board was "connected" as soon as the lab's board
service joined the bus, before any board page was open ("waiting for the board page" never showed); and
at 1280x900 and 1366x768 the Games table overflowed its panel (a click on "mark invalid" landed on the
data panel's Delete), at 1920x1080 the page scrolled sideways (the bias table's gaze column cut). Another
(2026-12-02) at 1280x900: the plan's step 10 showed ".0.", the Games table's headers broke letter by letter.
"""

from __future__ import annotations

import json
import time
import urllib.request
from pathlib import Path

import pytest

from pairplay.replay.studydata import StudyData
from pairplay.services.bus import Bus, BusOptions
from pairplay.services.console.server import StudyLabServer
from pairplay.services.protocol import StudyRunner, scripted_players

from labutil import open_page

STUDY = Path(__file__).parent / "data" / "pilot-study.toml"
PERSONAS = ["tatiana", "blind", "deaf", "vincent"]


def _api(server, path: str, body=None) -> dict:
    req = urllib.request.Request(f"{server.url}/api/console/{path}?token={server.token}",
                                 data=None if body is None else json.dumps(body).encode(),
                                 method="GET" if body is None else "POST", headers={"content-type": "application/json"})
    with urllib.request.urlopen(req, timeout=10) as r:
        return json.loads(r.read())


def test_the_board_is_connected_when_a_board_page_is_not_when_the_lab_joins_the_bus(browser, tmp_path):
    data = StudyData.create(tmp_path / "study", STUDY)
    with Bus(BusOptions()) as bus:
        server = StudyLabServer(StudyRunner(data, bus)).start()
        try:
            _api(server, "register", {"phase": "phase1", "count": 2, "consent": True})
            ctx = browser.new_context(viewport={"width": 1366, "height": 900}, bypass_csp=True)
            console = ctx.new_page()
            console.goto(server.console_url)
            console.click("#run-next")
            link = console.wait_for_selector("#board-link", timeout=30000)
            time.sleep(1.0)  # the lab's board service is on the bus by now (it was "connected" at once)
            assert _api(server, "state")["live"]["board"] is False
            assert console.inner_text("#live-board").startswith("waiting for the board page")
            board = open_page(browser, server.url + link.get_attribute("href"))
            console.wait_for_function("document.getElementById('live-board').textContent.startsWith('connected')",
                                      timeout=15000)
            assert _api(server, "state")["live"]["board"] is True
            board.context.close()
            console.wait_for_function("document.getElementById('live-board').textContent.startsWith('waiting')",
                                      timeout=15000)
            _api(server, "control/abort", {"reason": "the test is over"})
            deadline = time.monotonic() + 30
            while _api(server, "state")["busy"] and time.monotonic() < deadline:
                time.sleep(0.1)
            ctx.close()
        finally:
            server.close()


@pytest.fixture(scope="module")
def played(tmp_path_factory):
    """A study whose whole plan was played (8 games, a combination), some games marked invalid: full tables."""
    root = tmp_path_factory.mktemp("layout")
    data = StudyData.create(root / "study", STUDY)
    ids = [data.register(phase, consent=True) for phase in ("phase1", "phase1", "phase2", "phase2")]
    with Bus(BusOptions()) as bus:
        runner = StudyRunner(data, bus)
        runner.run_plan(scripted_players(runner, dict(zip(ids, PERSONAS))))
    return root / "study"


BUTTONS_CLICKABLE = """() => {
  const bad = [];
  for (const b of document.querySelectorAll('button')) {
    if (!b.offsetParent) continue;  // not shown
    b.scrollIntoView({block: 'center', inline: 'center'});
    const r = b.getBoundingClientRect();
    const at = document.elementFromPoint(r.left + r.width / 2, r.top + r.height / 2);
    if (!(at === b || b.contains(at))) bad.push(`${b.id || b.textContent} covered by ${at ? (at.id || at.tagName + ' ' + at.textContent.slice(0, 30)) : 'nothing'}`);
  }
  return bad;
}"""


# A new user's trial at 1280x900: the plan's numbers from 10 on were cut at the panel's edge (".0. p01: phase2
# game 1": the list's markers are drawn in its padding, which held one digit), and the Games table's headers
# broke letter by letter ("sessio n", "w h o": every cell could break anywhere, headers too).
WORDS_BROKEN = """() => {
  const bad = [];
  for (const th of document.querySelectorAll('th')) {
    const text = th.firstChild;
    if (!text || text.nodeType !== Node.TEXT_NODE) continue;
    let at = 0;
    for (const word of text.data.split(' ')) {
      const range = document.createRange();
      range.setStart(text, at); range.setEnd(text, at + word.length);
      if (word && range.getClientRects().length > 1) bad.push(word);
      at += word.length + 1;
    }
  }
  return bad;
}"""
MARKERS_CUT = """() => {
  const ol = document.getElementById('plan');
  const item = ol.querySelector('li:last-child');
  const style = getComputedStyle(item);
  const ctx = document.createElement('canvas').getContext('2d');
  ctx.font = `${style.fontWeight} ${style.fontSize} ${style.fontFamily}`;
  // the widest marker of a plan of up to 99 steps (this one has fewer: the trial's had 10+), in the items' font
  const marker = ctx.measureText(`${Math.max(ol.children.length, 99)}. `).width;
  return [ol.children.length, marker, parseFloat(getComputedStyle(ol).paddingLeft)];
}"""


@pytest.mark.parametrize("width,height", [(1280, 900), (1366, 768), (1920, 1080), (1024, 768)])
def test_every_button_is_clickable_no_header_breaks_in_a_word_and_the_page_never_scrolls_sideways(
        browser, played, width, height):
    with Bus(BusOptions()) as bus:
        server = StudyLabServer(StudyRunner(StudyData(played), bus)).start()
        try:
            ctx = browser.new_context(viewport={"width": width, "height": height}, bypass_csp=True)
            page = ctx.new_page()
            page.goto(server.console_url)
            page.wait_for_function("document.querySelectorAll('#games tbody tr').length == 8", timeout=15000)
            page.wait_for_selector("#rules-phase2", timeout=15000)
            sideways = page.evaluate("[document.documentElement.scrollWidth, document.documentElement.clientWidth]")
            assert sideways[0] <= sideways[1], f"the page scrolls sideways at {width}x{height}: {sideways}"
            assert page.evaluate(BUTTONS_CLICKABLE) == []
            assert page.evaluate(WORDS_BROKEN) == []
            steps, marker, room = page.evaluate(MARKERS_CUT)
            assert steps > 0 and marker <= room, (steps, marker, room)
            ctx.close()
        finally:
            server.close()


def test_an_id_in_the_key_file_only_is_listed_as_what_it_is(browser, tmp_path):
    """Bob's registration and participants.csv row removed by hand, his key-file line left: `protocol status` said
    it, the console listed p01 alone (the experimenter saw nothing wrong). It lists p02 as not registered, in the
    state and on the page, and not as a participant (no export or deletion is offered for it)."""
    data = StudyData.create(tmp_path / "study", STUDY, tmp_path / "keys" / "k.csv")
    assert [data.register("phase1", name) for name in ("Alice", "Bob")] == ["p01", "p02"]
    data.write_tables()
    journal, table = data.folder / "journal.jsonl", data.folder / "participants.csv"
    journal.write_bytes(b"".join(line for line in journal.read_bytes().splitlines(keepends=True)
                                 if not (b'"ParticipantRegistered"' in line and b'"p02"' in line)))
    table.write_text("".join(r for r in table.read_text().splitlines(keepends=True) if not r.startswith("p02,")))
    note = ("in the key file only: not registered (a crash cut its registration, or a hand edit): no data here; "
            "the id is not given again")
    with Bus(BusOptions()) as bus:
        server = StudyLabServer(StudyRunner(StudyData(data.folder), bus)).start()
        try:
            state = _api(server, "state")
            assert [p["id"] for p in state["participants"]] == ["p01"], state["participants"]
            assert state["unregistered"] == [{"id": "p02", "note": note}], state
            ctx = browser.new_context(viewport={"width": 1366, "height": 900}, bypass_csp=True)
            page = ctx.new_page()
            page.goto(server.console_url)
            page.wait_for_function("document.querySelectorAll('#participants li').length == 2", timeout=15000)
            assert page.inner_text("#participants li.unregistered") == f"p02: {note}"
            assert page.eval_on_selector_all("#data-participant option", "os => os.map(o => o.value)") == ["p01"]
            ctx.close()
        finally:
            server.close()
