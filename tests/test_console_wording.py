"""What the console and the questionnaire page say, in a real headless Chromium (trial27 F12).

F12a: a new study nobody is registered in: the console read "next: combine the policies of the players before
phase2 into its bias policy" while `protocol status` said "nobody is registered: `pairplay protocol register ...`
first" (the state's `next` was the blocked combination, so the page's own "nobody is registered" never showed).
F12b: a participant who reloaded the questionnaire page after sending it saw "this questionnaire link is not the
current game's", in the error style, instead of the thanks.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

from pairplay.replay.studydata import StudyData
from pairplay.services.bus import Bus, BusOptions
from pairplay.services.console.server import StudyLabServer
from pairplay.services.protocol import StudyRunner
from pairplay.services.scripted import ScriptedPlayer

from test_console_browser import answer_questionnaire
from test_console_layout import _api

STUDY = Path(__file__).parent / "data" / "pilot-study.toml"


def open_page(browser, url: str):
    """A page in its own context (another person's tab)."""
    page = browser.new_context(viewport={"width": 1366, "height": 900}, bypass_csp=True).new_page()
    page.goto(url)
    return page


def test_a_new_study_says_to_register_first_as_protocol_status_does(browser, tmp_path, pairplay_cli):
    data = StudyData.create(tmp_path / "study", STUDY)
    status = pairplay_cli("protocol", "status", data.folder)
    assert status.stdout.startswith("nobody is registered"), status.stdout
    with Bus(BusOptions()) as bus:
        server = StudyLabServer(StudyRunner(data, bus)).start()
        try:
            assert _api(server, "state")["next"] is None  # not the blocked combination
            page = open_page(browser, server.console_url)
            page.wait_for_function("document.getElementById('next-step').textContent !== ''", timeout=15000)
            assert page.inner_text("#next-step") == "nobody is registered: register participants first"
            assert page.is_disabled("#run-next")
            _api(server, "register", {"phase": "phase1", "count": 1})
            page.wait_for_function("document.getElementById('next-step').textContent.startsWith('next: p01')",
                                   timeout=15000)
            page.context.close()
        finally:
            server.close()


def test_a_questionnaire_page_reloaded_after_sending_thanks_the_participant(browser, tmp_path):
    data = StudyData.create(tmp_path / "study", STUDY)
    data.register_many("phase1")
    with Bus(BusOptions()) as bus:
        runner = StudyRunner(data, bus)
        server = StudyLabServer(runner).start()
        try:
            # a persona plays the cards on the bus and leaves the questionnaire to the page (no questions)
            player = ScriptedPlayer("tatiana", press_wrong=False, think_ms=0.0, glance_ms=0.0)
            game = threading.Thread(target=runner.run_game, args=("p01", "phase1", 0, player), daemon=True)
            game.start()
            while runner.live.state != "questionnaire" and game.is_alive():
                time.sleep(0.05)
            link = _api(server, "state")["live"]["questionnaire_url"]
            page = open_page(browser, server.url + link)
            answer_questionnaire(page, "tatiana")
            game.join(60)
            assert not game.is_alive() and data.state.games[runner.live.session or
                                                           next(iter(data.state.games))].ended.questionnaire
            page.reload()
            page.wait_for_function("document.getElementById('q-status').textContent !== ''", timeout=15000)
            assert page.inner_text("#q-status") == "Thank you! Your answers are recorded."
            assert page.get_attribute("#q-status", "class") != "error"
            assert page.inner_html("#q-form") == ""
            page.context.close()
        finally:
            server.close()
