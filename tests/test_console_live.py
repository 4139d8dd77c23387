"""A served study's pages under real use (trial27), in a real headless Chromium, one study for the module.

Rules tested: the participant's page follows the game's true end (an aborted game asks no
questionnaire: the board says it was stopped and the questionnaire link is dead; a skipped
questionnaire closes on the page that shows it); the console's refusal stays on screen until the
experimenter acts again; a console whose server does not answer says so and turns its controls off
until a poll gets an answer.
"""

from __future__ import annotations

import json
import threading
import urllib.error
import urllib.request
from pathlib import Path

import pytest

from labutil import open_page, wait_phase
from pairplay.replay.studydata import StudyData
from pairplay.services.bus import Bus, BusOptions
from pairplay.services.console.server import StudyLabServer
from pairplay.services.protocol import StudyRunner
from pairplay.services.scripted import ScriptedPlayer

STUDY = Path(__file__).parent / "data" / "pilot-study.toml"


@pytest.fixture(scope="module")
def served(browser, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("served")
    study = tmp / "study.toml"
    # 1-round games (a 1-round pi-reuse phase reuses only if told to), missed pairs turned back quickly
    study.write_text(STUDY.read_text().replace("rounds = 2", "rounds = 1")
                     .replace("[study]", "[study]\nturn_back_ms = 30")
                     .replace('preset = "human-phase2"', 'preset = "human-phase2"\nlearner = { reuse_rounds = 1 }'))
    data = StudyData.create(tmp / "study", study)
    with Bus(BusOptions()) as bus:
        runner = StudyRunner(data, bus)
        server = StudyLabServer(runner).start()
        ctx = browser.new_context(viewport={"width": 1366, "height": 900}, bypass_csp=True)
        console = ctx.new_page()
        console.errors = []
        console.on("pageerror", lambda e: console.errors.append(str(e)))
        console.goto(server.console_url)
        try:
            yield data, runner, server, console
        finally:
            ctx.close()
            server.close()


def status_of(url: str) -> int:
    try:
        with urllib.request.urlopen(url, timeout=10) as r:
            return r.status
    except urllib.error.HTTPError as err:
        return err.code


def post(server, path: str, body: dict) -> dict:
    req = urllib.request.Request(f"{server.url}{path}?token={server.token}", data=json.dumps(body).encode(),
                                 headers={"content-type": "application/json"}, method="POST")
    with urllib.request.urlopen(req, timeout=10) as r:
        return json.loads(r.read())


def message(console) -> tuple[str, str]:
    return console.inner_text("#message"), console.get_attribute("#message", "class") or ""


def test_an_aborted_game_asks_no_questionnaire(browser, served):
    data, runner, server, console = served
    console.fill("#register-count", "1")
    console.check("#register-consent")  # they signed the consent form: a person plays only then
    console.click("#register")
    console.wait_for_function("document.querySelectorAll('#participants li').length == 1", timeout=10000)
    assert "consent: the study's form (its version not named) given " in console.inner_text("#participants li")
    console.click("#run-next")
    link = console.wait_for_selector("#board-link", timeout=30000)
    q_link = console.wait_for_selector("#questionnaire-link", timeout=10000).get_attribute("href")
    board = open_page(browser, server.url + link.get_attribute("href"))
    wait_phase(board, "first")
    board.click("[data-card='0']")
    wait_phase(board, "looking", "thinking", "second")
    console.fill("#abort-reason", "robot froze")
    console.click("#abort")
    board.wait_for_function("document.body.dataset.phase === 'over'", timeout=15000)
    # the board says the game was stopped, and does not turn into a questionnaire that refuses the answers
    board.wait_for_function("document.getElementById('prompt').textContent === 'The game was stopped. Thank you!'",
                            timeout=10000)
    console.wait_for_function("document.getElementById('live-state').textContent === 'idle'", timeout=15000)
    assert "/s/" in board.url and "questionnaire" not in board.url
    assert status_of(server.url + q_link.replace("/questionnaire?", "/api/questionnaire?")) == 403
    games = list(data.state.games.values())
    assert [g.ended.outcome for g in games] == ["aborted"]
    assert board.errors == []
    board.context.close()


def test_a_skipped_questionnaire_closes_on_the_page(browser, served):
    data, runner, server, console = served
    step = data.next_step()
    # a scripted player that answers nothing: the questionnaire waits for a person
    player = ScriptedPlayer("tatiana", think_ms=0.0, glance_ms=0.0)
    game = threading.Thread(target=runner.run_game, args=(step.participant, step.phase, step.game),
                            kwargs={"player": player}, daemon=True)
    game.start()
    console.wait_for_function("document.getElementById('live-state').textContent === 'questionnaire'",
                              timeout=60000)
    q_link = console.get_attribute("#questionnaire-link", "href")
    q = browser.new_context(bypass_csp=True).new_page()
    q.goto(server.url + q_link)
    q.wait_for_selector("#q-send", timeout=10000)
    # a poll never answered (a half-open connection) is said, and the page goes on once polls are answered
    polls = lambda url: "/api/questionnaire?" in url  # noqa: E731 (the same predicate unroutes it)
    q.route(polls, lambda route: None)
    q.wait_for_function("document.getElementById('q-status').textContent === "
                        "'No connection to the lab server: retrying…'", timeout=20000)
    q.unroute(polls)
    q.wait_for_function("document.getElementById('q-status').textContent === ''", timeout=10000)
    console.click("#skip-questionnaire")
    game.join(30)
    assert not game.is_alive()
    q.wait_for_function("document.getElementById('q-status').textContent === 'The questionnaire is closed. Thank you!'",
                        timeout=10000)
    assert q.query_selector("#q-send") is None  # the form is gone: nobody answers into the void
    q.context.close()


def test_a_refusal_stays_until_the_experimenter_acts_again(served):
    data, runner, server, console = served
    console.select_option("#data-participant", "p01")
    console.fill("#delete-confirm", "not-p01")
    console.click("#delete")
    console.wait_for_function("document.getElementById('message').className === 'error'", timeout=10000)
    refusal = message(console)
    # the console redraws (a registration made elsewhere shows up): the refusal is still there
    post(server, "/api/console/register", {"phase": "phase1", "count": 1})
    console.wait_for_function("document.querySelectorAll('#participants li').length == 2", timeout=10000)
    assert message(console) == refusal
    # the experimenter acts again: the refusal goes (what replaces it, the act's own line or the running
    # step's, is not held: the next poll may replace it)
    console.click("#register")
    console.wait_for_function("document.querySelectorAll('#participants li').length == 3", timeout=10000)
    console.wait_for_function(f"document.getElementById('message').textContent !== {refusal[0]!r}", timeout=10000)
    assert console.errors == []  # a refused button is said, not thrown at the page


def test_the_console_shows_what_the_game_refused_a_late_touch_among_them(browser, served):
    """Trial32 G: a board whose touches were all refused as late said nothing on the console; the running game's
    refusals are now counted there, with the last one's reason."""
    data, runner, server, console = served
    console.click("#run-next")
    link = console.wait_for_selector("#board-link", timeout=30000)
    board = open_page(browser, server.url + link.get_attribute("href"))
    wait_phase(board, "first")
    board.wait_for_function("window.pairplay.canTouch()")
    assert console.inner_text("#live-refused") == ""
    board.evaluate("""() => { const p = window.pairplay, s = p.state;
        p.link.send({type: "pick", id: p.nextId(), round: s.round, turn: s.turn, card: 4,
                     page_ms: window.pairplayLab.now() - 20000}); }""")
    console.wait_for_function("document.getElementById('live-refused').textContent.startsWith('1 (last: late: ')",
                              timeout=15000)
    board.wait_for_function("window.pairplay.canTouch()", timeout=15000)  # reconnected (test_lab_heartbeat)
    console.fill("#abort-reason", "test over")
    console.click("#abort")
    console.wait_for_function("document.getElementById('live-state').textContent === 'idle'", timeout=15000)
    assert board.errors == [] and console.errors == []
    board.context.close()


def test_a_console_whose_server_does_not_answer_says_so(served):
    data, runner, server, console = served
    # the server stops answering the console's polls (as when it is gone: fetch fails)
    console.route("**/api/console/state*", lambda route: route.abort())
    console.wait_for_function("document.getElementById('message').textContent.startsWith("
                              "'the lab server does not answer')", timeout=10000)
    assert console.evaluate("[...document.querySelectorAll('button')].every(b => b.disabled)")
    console.unroute("**/api/console/state*")
    console.wait_for_function("!document.getElementById('register').disabled", timeout=10000)
    assert not console.inner_text("#message").startswith("the lab server does not answer")
    assert console.is_enabled("#run-next") and console.is_enabled("#export")
    # a poll that is never answered (a half-open connection: the network dropped without closing it) is no
    # answer either: before, the fetch waited for ever and the console kept its last view without a word
    console.route("**/api/console/state*", lambda route: None)
    console.wait_for_function("document.getElementById('message').textContent.startsWith("
                              "'the lab server does not answer')", timeout=20000)
    console.unroute("**/api/console/state*")
    console.wait_for_function("!document.getElementById('register').disabled", timeout=10000)
    # the real thing: the server stops
    server.close()
    console.wait_for_function("document.getElementById('message').textContent.startsWith("
                              "'the lab server does not answer')", timeout=10000)
    assert console.is_disabled("#register")
