"""The whole two-phase protocol from the experimenter's console, in a real headless Chromium.

Debian's /usr/bin/chromium driven by Playwright (never a browser download). The
experimenter registers 4 participants on the console page, runs every step of
the plan by clicking "Run the next step" (4 phase-1 games, the combination, 4
phase-2 games), and each game's questionnaire is answered on its own page by
clicks. The cards are touched by scripted participants (core personas,
services/scripted.py) that join each game's bus as its board once the console
says the game waits for one. Then one participant is exported and another
deleted from the console, the report is written from it, and
`pairplay replay --verify` passes on every recording the study produced.
Set PAIRPLAY_DOCS_SHOTS=docs to refresh docs/console*.png.
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
import zipfile
from pathlib import Path

import pytest

from pairplay.replay.reader import read_log
from pairplay.replay.studydata import StudyData
from pairplay.services.bus import Bus, BusOptions
from pairplay.services.console.server import ConsoleServer
from pairplay.services.protocol import StudyRunner
from pairplay.services.runner import Node
from pairplay.services.scripted import ScriptedPlayer, answers_for

sync_playwright = pytest.importorskip("playwright.sync_api").sync_playwright
CHROMIUM = "/usr/bin/chromium"
FLAGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
         "--disable-sync", "--no-first-run"]
STUDY = Path(__file__).parent / "data" / "pilot-study.toml"
PERSONAS = {"p01": "tatiana", "p02": "blind", "p03": "deaf", "p04": "vincent"}

pytestmark = pytest.mark.skipif(not Path(CHROMIUM).exists(), reason="Debian's chromium is not installed")


class Boards:
    """Joins every game that waits for its board with the participant's scripted player."""

    def __init__(self, runner: StudyRunner, bus: Bus):
        self.runner, self.bus = runner, bus
        self.stop = threading.Event()
        self.joined: dict[str, ScriptedPlayer] = {}
        self.thread = threading.Thread(target=self.run, daemon=True)
        self.thread.start()

    def run(self) -> None:
        while not self.stop.wait(0.02):
            live = self.runner.live
            if live.state == "playing" and live.session and live.session not in self.joined:
                player = ScriptedPlayer(PERSONAS[live.participant])  # answers come from the page
                self.joined[live.session] = player
                node = Node(self.bus, player, live.session, clock=player.clock, resume=False)
                node.start()
                node.run_in_thread(self.stop)


def answer_questionnaire(page, persona_key: str, slow_clicks: bool = False) -> None:
    """Answer every item of the questionnaire page by clicks, as the persona would."""
    from pairplay.core.personas import persona
    from pairplay.schemas.study import Item
    page.wait_for_selector("#q-send", timeout=20000)
    items = []
    for fs in page.query_selector_all("#q-form fieldset"):
        item_id, kind = fs.get_attribute("id")[5:], fs.get_attribute("data-kind")
        values = [i.get_attribute("value") for i in fs.query_selector_all("input")]
        items.append(Item(id=item_id, text="?", kind=kind, scale=len(values) if kind == "likert" else 5,
                          options=values if kind == "choice" else []))
    answers = answers_for(persona(persona_key), items)
    if slow_clicks:  # each answer a Playwright click (the first questionnaire)
        for item_id, value in answers.items():
            if next(i.kind for i in items if i.id == item_id) == "text":
                page.fill(f"#item-{item_id} textarea", value)
            else:
                page.click(f"#item-{item_id} label:has(input[value='{value}'])")
    else:  # the same clicks dispatched in the page, without a round trip each (fast)
        page.evaluate("""(answers) => { for (const [id, v] of Object.entries(answers)) {
            const ta = document.querySelector(`#item-${id} textarea`);
            if (ta) { ta.value = v; continue; }
            document.querySelector(`#item-${id} input[value="${v}"]`).closest("label").click(); } }""", answers)
    page.click("#q-send")
    page.wait_for_selector("text=Your answers are recorded", timeout=10000)


FULL = [pytest.param("none", 2, id="fast"),
        # the thesis's 5-round games with the virtual robot performing every suggestion
        pytest.param("virtual", 5, id="full-thesis-rounds", marks=pytest.mark.slow)]


@pytest.mark.parametrize("robot,rounds", FULL)
def test_the_whole_protocol_from_the_console(tmp_path, robot, rounds):
    study = tmp_path / "study.toml"
    study.write_text(STUDY.read_text().replace('robot = "none"', f'robot = "{robot}"')
                     .replace("rounds = 2", f"rounds = {rounds}"))
    data = StudyData.create(tmp_path / "study", study)
    T0 = time.perf_counter()
    shots = Path(os.environ.get("PAIRPLAY_DOCS_SHOTS", tmp_path))
    with Bus(BusOptions()) as bus:
        runner = StudyRunner(data, bus)
        server = ConsoleServer(runner).start()
        boards = Boards(runner, bus)
        try:
            with sync_playwright() as pw:
                browser = pw.chromium.launch(executable_path=CHROMIUM, headless=True, args=FLAGS)
                page = browser.new_page(viewport={"width": 1366, "height": 900})
                errors: list[str] = []
                page.on("pageerror", lambda e: errors.append(str(e)))
                page.goto(server.url + "/console?token=wrong")
                page.wait_for_selector("#message.error", timeout=10000)
                assert "token" in page.inner_text("#message")
                page.goto(server.console_url)
                for phase in ("phase1", "phase2"):
                    page.select_option("#register-phase", phase)
                    page.fill("#register-count", "2")
                    page.click("#register")
                    page.wait_for_function(f"document.querySelectorAll('#participants li').length == "
                                           f"{2 if phase == 'phase1' else 4}", timeout=10000)
                steps = 0
                while True:
                    page.wait_for_function("!document.getElementById('run-next').disabled || "
                                           "document.getElementById('next-step').textContent.includes('complete')",
                                           timeout=30000)
                    if "complete" in page.inner_text("#next-step"):
                        break
                    label = page.inner_text("#next-step")
                    print(f"{time.perf_counter() - T0:6.1f} {label}", flush=True)
                    page.click("#run-next")
                    steps += 1
                    if "combine" in label:
                        page.wait_for_selector("#rules-phase2", timeout=30000)
                        if steps == 5:
                            page.screenshot(path=str(shots / "console-combined.png"), full_page=True)
                        continue
                    who = label.split("next: ")[1].split(":")[0]
                    # the questionnaire page opens with the game (as on the board) and waits for its end
                    link = page.wait_for_selector("#questionnaire-link", timeout=30000)
                    q = browser.new_page(viewport={"width": 1024, "height": 600})
                    q.goto(server.url + link.get_attribute("href"))
                    if steps == 6:
                        page.wait_for_function("document.getElementById('live-round').textContent.startsWith('2')",
                                               timeout=30000)
                        page.screenshot(path=str(shots / "console.png"), full_page=False)
                    answer_questionnaire(q, PERSONAS[who], slow_clicks=steps == 1)
                    if steps == 1:
                        q.screenshot(path=str(shots / "questionnaire.png"))
                    q.close()
                assert steps == 9, steps
                print(f"{time.perf_counter() - T0:6.1f} plan done", flush=True)

                sessions = [g for g in data.state.games.values()]
                assert len(sessions) == 8 and all(g.valid_complete and g.ended.questionnaire for g in sessions)
                recordings = [data.folder / g.recording for g in sessions]
                page.select_option("#data-participant", "p02")
                page.click("#export")
                page.wait_for_selector("#export-link", timeout=10000)
                with zipfile.ZipFile(data.folder / "exports" / "p02.zip") as z:
                    assert "README.txt" in z.namelist() and "answers.csv" in z.namelist()
                    assert sum(n.endswith(".mcap") for n in z.namelist()) == 3
                page.select_option("#data-participant", "p03")
                page.fill("#delete-confirm", "p03")
                page.click("#delete")
                page.wait_for_function("document.getElementById('data-result').textContent.includes('deleted p03')",
                                       timeout=10000)
                page.click("#report")
                page.wait_for_selector("#report-md", timeout=30000)
                assert not errors, errors
                browser.close()
        finally:
            boards.stop.set()
            server.close()
    assert data.state.combined["phase2"].users == ["human:p01", "human:p02"]
    deleted = [r for r in recordings if "-p03-" in r.name]
    assert len(deleted) == 1 and not deleted[0].exists()
    report = (data.folder / "report" / "report.md").read_text()
    assert "returning against new users" in report and "p03" not in report
    for r in recordings:
        if r.exists():
            answered = read_log(r).of("QuestionnaireAnswered")
            assert len(answered) == 1 and answered[0].source == "board"
    print(f"{time.perf_counter() - T0:6.1f} browser done", flush=True)
    # every recording the study produced, the deleted one excepted, verifies from the command line
    kept = [r for r in recordings if r.exists()]
    assert len(kept) == 7
    # (one interpreter runs the verb on each file: the same code path, without 7 start-ups)
    script = ("import sys; from pairplay.cli.main import main; "
              "sys.exit(max(main(['replay', f, '--verify']) for f in sys.argv[1:]))")
    out = subprocess.run([sys.executable, "-c", script, *map(str, kept)], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0 and out.stdout.count("verify: PASS") == 7, (out.stdout[-800:], out.stderr[-800:])
