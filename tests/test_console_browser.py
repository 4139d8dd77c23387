"""The whole two-phase protocol from the experimenter's console, in a real headless Chromium.

Debian's /usr/bin/chromium driven by Playwright (never a browser download). The
experimenter registers 4 participants on the console page and runs every step of
the plan by clicking "Run the next step" (4 phase-1 games, the combination, 4
phase-2 games). Each game of a board player is played on its board page (the lab's,
linked from the console) by clicks, a core persona choosing every card and the wrong-suggestion
button (services/scripted.py reads the game's events on the bus); when the game
is over the board page becomes the questionnaire, answered by clicks. Then one
participant is exported and another deleted from the console, the report is
written from it, and `pairplay replay --verify` passes on every recording.
Set PAIRPLAY_DOCS_SHOTS=docs to refresh docs/console*.png and docs/questionnaire.png.
"""

from __future__ import annotations

import os
import queue
import time
import zipfile
from pathlib import Path

import pytest

from pairplay.replay.reader import read_log
from pairplay.replay.studydata import StudyData
from pairplay.schemas import events as ev
from pairplay.services.bus import Bus, BusOptions
from pairplay.services.console.server import StudyLabServer
from pairplay.services.node import Driver
from pairplay.services.protocol import StudyRunner
from pairplay.services.scripted import ScriptedPlayer, answers_for

from labutil import card_centers, open_page

STUDY = Path(__file__).parent / "data" / "pilot-study.toml"
PERSONAS = {"p01": "tatiana", "p02": "blind", "p03": "deaf", "p04": "vincent"}


def play_on_the_board(page, inbox: queue.Queue, session: str, persona_key: str) -> int:
    """The persona plays the game on the board page: it reads the game's events from the bus and
    clicks what it chose (cards, the wrong-suggestion button); returns the clicks made."""
    player = Driver(ScriptedPlayer(persona_key), session, clock=time.time_ns)
    centers = card_centers(page)
    clicks = 0
    while not player.logic.done:
        key, payload = inbox.get(timeout=30)
        if f"/{session}/" not in key:
            continue
        for out in player.receive(key, payload):
            at = f"window.pairplay.state.round === {out.round} && window.pairplay.state.turn === {out.turn}"
            if isinstance(out, ev.CardPicked):
                page.wait_for_function(f"{at} && window.pairplay.canTouch()", timeout=10000, polling=5)
                page.mouse.click(*centers[out.card])
            elif isinstance(out, ev.WrongSuggestionPressed):
                # a real click at the button's centre once it is enabled (where it is then: the bar's texts
                # may move it), without the locator's actionability waits (a game presses it up to ~30 times)
                where = page.wait_for_function(
                    f"{at} && !document.getElementById('wrong').disabled && "
                    "(r => [r.x + r.width / 2, r.y + r.height / 2])(document.getElementById('wrong').getBoundingClientRect())",
                    timeout=10000, polling=5)
                page.mouse.click(*where.json_value())
            clicks += 1
    return clicks


def answer_questionnaire(page, persona_key: str, slow_clicks: bool = False, shot: Path | None = None) -> None:
    """Answer every item of the questionnaire page by clicks, as the persona would."""
    from pairplay.core.personas import persona
    from pairplay.schemas.study import Item
    page.wait_for_selector("#q-send", timeout=20000)
    items = []
    # each fieldset's id, kind and input values in one evaluate (not ~80 element round trips)
    fieldsets = page.evaluate("""() => Array.from(document.querySelectorAll("#q-form fieldset"), fs =>
        [fs.id, fs.getAttribute("data-kind"), Array.from(fs.querySelectorAll("input"), i => i.getAttribute("value"))])""")
    for fs_id, kind, values in fieldsets:
        item_id = fs_id[5:]
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
    if shot is not None:
        page.screenshot(path=str(shot))
    page.click("#q-send")
    page.wait_for_selector("text=Your answers are recorded", timeout=10000)


FULL = [
    # fast (default): 1-round games; p01 (its first phase-1 game and phase 2) and p03 (new in phase 2) play on
    # the board page by clicks, p02 and p04 are scripted on the bus (the console's dress-rehearsal players), and
    # so is p01's second phase-1 game: a participant's later game on the board is p01's phase-2 one (the
    # returning questions too), so a third board game of 1 round proved nothing more, for a quarter of the clicks
    pytest.param("none", 1, ("p02", "p04"), ("p01: phase1 game 2",), id="fast"),
    # the thesis's 5-round games, everyone on the board page, the virtual robot performing every suggestion
    pytest.param("virtual", 5, (), (), id="full-thesis-rounds", marks=pytest.mark.slow)]


@pytest.mark.parametrize("robot,rounds,on_the_bus,games_on_the_bus", FULL)
def test_the_whole_protocol_from_the_console(browser, tmp_path, capsys, robot, rounds, on_the_bus, games_on_the_bus):
    study = tmp_path / "study.toml"
    # clicks are fast: learn from every turn (no ignore window); missed pairs turn back quickly
    study.write_text(STUDY.read_text().replace('robot = "none"', f'robot = "{robot}"')
                     .replace("rounds = 2", f"rounds = {rounds}").replace("ignore_window_ms = 1500", "ignore_window_ms = 0")
                     .replace("[study]", "[study]\nturn_back_ms = 30")
                     # a 1-round pi-reuse phase under human-phase2 never reuses (refused): its one round reuses
                     .replace('preset = "human-phase2"', 'preset = "human-phase2"' + (
                         "\nlearner = { reuse_rounds = 1 }" if rounds == 1 else "")))
    data = StudyData.create(tmp_path / "study", study)
    # the docs' screenshots only when asked for: nothing asserts on them (four PNG encodes of CPU a run)
    shots = Path(os.environ["PAIRPLAY_DOCS_SHOTS"]) if os.environ.get("PAIRPLAY_DOCS_SHOTS") else None
    inbox: queue.Queue = queue.Queue()
    with Bus(BusOptions()) as bus:
        bus.subscribe("pairplay/**", lambda k, p: inbox.put((k, p)))
        runner = StudyRunner(data, bus)
        runner.scripted = {pid: PERSONAS[pid] for pid in on_the_bus}
        server = StudyLabServer(runner).start()
        try:
            # bypass_csp: the lab's content security policy forbids the test's evaluated predicates, not the pages
            console_ctx = browser.new_context(viewport={"width": 1366, "height": 900}, bypass_csp=True)
            page = console_ctx.new_page()
            errors: list[str] = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(server.url + "/console?token=wrong")
            page.wait_for_selector("#message.error", timeout=10000)
            assert "token" in page.inner_text("#message")
            page.goto(server.console_url)
            for phase in ("phase1", "phase2"):
                page.select_option("#register-phase", phase)
                page.fill("#register-count", "2")
                page.check("#register-consent")  # they signed the consent form: recorded with them
                page.click("#register")
                page.wait_for_function(f"document.querySelectorAll('#participants li').length == "
                                       f"{2 if phase == 'phase1' else 4}", timeout=10000)
            steps, clicks = 0, 0
            while True:
                page.wait_for_function("!document.getElementById('run-next').disabled || "
                                       "document.getElementById('next-step').textContent.includes('complete')",
                                       timeout=30000)
                if "complete" in page.inner_text("#next-step"):
                    break
                label = page.inner_text("#next-step")
                who = label.split("next: ")[1].split(":")[0] if "combine" not in label else ""
                bus_game = label[6:] in games_on_the_bus  # this one game of a board player, scripted
                runner.scripted = {pid: PERSONAS[pid] for pid in on_the_bus + ((who,) if bus_game else ())}
                page.click("#run-next")
                steps += 1
                if "combine" in label:
                    page.wait_for_selector("#rules-phase2", timeout=30000)
                    if shots:
                        page.screenshot(path=str(shots / "console-combined.png"), full_page=True)
                    continue
                if who in on_the_bus or bus_game:
                    page.wait_for_function(f"document.getElementById('message').textContent.startsWith("
                                           f"'{label[6:]}: ') && !document.getElementById('message')"
                                           ".textContent.endsWith('running')", timeout=30000)
                    continue
                link = page.wait_for_selector("#board-link", timeout=30000)
                session = runner.live.session
                board = open_page(browser, server.url + link.get_attribute("href"))
                if steps == 8 and shots:
                    board.screenshot(path=str(shots / "study-board.png"))
                clicks += play_on_the_board(board, inbox, session, PERSONAS[who])
                if steps == 8:
                    page.wait_for_function("document.getElementById('live-state').textContent == 'questionnaire'",
                                           timeout=30000)
                    if shots:
                        page.screenshot(path=str(shots / "console.png"), full_page=False)
                # the board page becomes the questionnaire once the game is over
                answer_questionnaire(board, PERSONAS[who], slow_clicks=steps == 1,
                                     shot=shots / "questionnaire.png" if shots and steps == 1 else None)
                assert board.errors == []
                board.context.close()
            assert steps == 9, steps

            games = list(data.state.games.values())
            assert len(games) == 8 and all(g.valid_complete and g.ended.questionnaire for g in games)
            recordings = [data.folder / g.recording for g in games]
            # the board players' games played on the bus (games_on_the_bus), said so in the study's data
            scripted_games = {r.name for g, r in zip(games, recordings)
                              if g.scripted and not any(f"-{pid}-" in r.name for pid in on_the_bus)}
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
            console_ctx.close()
        finally:
            server.close()
    assert data.state.combined["phase2"].users == ["human:p01", "human:p02"]
    deleted = [r for r in recordings if "-p03-" in r.name]
    assert len(deleted) == 1 and not deleted[0].exists()
    report = (data.folder / "report" / "report.md").read_text()
    assert "returning against new users" in report and "p03" not in report
    clicked = 0
    for r in recordings:
        if r.exists():
            log = read_log(r)
            answered = log.of("QuestionnaireAnswered")
            assert len(answered) == 1 and answered[0].source == "board"
            if not any(f"-{pid}-" in r.name for pid in on_the_bus) and r.name not in scripted_games:
                assert all(p.page_time_ms > 0 for p in log.of("CardPicked"))  # touched on the page
            clicked += len(log.of("CardPicked")) + len(log.of("WrongSuggestionPressed"))
    assert clicked > 20 * (4 - len(on_the_bus)) * rounds / 2
    assert len(scripted_games) == len(games_on_the_bus)
    # every recording the study produced, the deleted one excepted, verifies from the command line
    kept = [r for r in recordings if r.exists()]
    assert len(kept) == 7
    # (the command line's own entry, run here on each file: the same code path without an interpreter's start
    # and pairplay's import, ~1.2 s of CPU, for what the verb says of the files)
    from pairplay.cli.main import main
    codes = [main(["replay", str(r), "--verify"]) for r in kept]
    out = capsys.readouterr()
    assert codes == [0] * 7 and out.out.count("verify: PASS") == 7, (out.out[-800:], out.err[-800:])
