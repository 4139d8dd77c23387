"""Photograph the lab's pages for the docs: docs/lab-board.png and docs/lab-mirror.png.

Rule: a real lab session (virtual robot) played by clicks in Debian's headless
Chromium (Playwright with executable_path; never `playwright install`) until
some pairs are found and the open suggestion has a visual part with a region
to point at (pressing "wrong suggestion" for another one if needed), then the
board at 1024 x 600 and the mirror at 1280 x 720.

    .venv/bin/python tools/lab_screenshots.py docs
"""

from __future__ import annotations

import sys
import tempfile
import threading
from pathlib import Path

from playwright.sync_api import sync_playwright

from pairplay.schemas.config import LearnerConfig
from pairplay.schemas.session import SessionConfig, learner_overrides
from pairplay.services.lab.server import run_lab

ARGS = ["--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--no-first-run", "--disable-extensions"]


def main(out: Path) -> None:
    config = SessionConfig(session="p07-phase1-g0", participant="human:p07", seed=11, rounds=5,
                           observed_source="first-pick", ignore_rule="time", ignore_clock="page",
                           turn_back_ms=0.0, learner=learner_overrides(LearnerConfig.human_phase1(5)))
    with tempfile.TemporaryDirectory() as tmp:
        ready, stop, box = threading.Event(), threading.Event(), {}
        t = threading.Thread(target=lambda: run_lab(config, Path(tmp) / "s.mcap", stop=stop, linger_s=0.0,
                                                    on_ready=lambda urls, bus: (box.update(urls=urls), ready.set())))
        t.start()
        ready.wait(30)
        try:
            with sync_playwright() as pw:
                browser = pw.chromium.launch(executable_path="/usr/bin/chromium", args=ARGS)
                ctx = dict(bypass_csp=True, device_scale_factor=1)
                board = browser.new_context(viewport={"width": 1024, "height": 600}, **ctx).new_page()
                board.goto(box["urls"].board)
                mirror = browser.new_context(viewport={"width": 1280, "height": 720}, **ctx).new_page()
                mirror.goto(box["urls"].mirror)
                board.wait_for_function("window.pairplay && window.pairplay.state && window.pairplay.canTouch()")
                faces: dict[int, int] = {}

                def click(card, second=False):
                    board.wait_for_function("window.pairplay.canTouch()")
                    turns = board.evaluate("window.pairplay.state.last_turn ? window.pairplay.state.last_turn.id : 0")
                    board.click(f"[data-card='{card}']")
                    if not second:
                        board.wait_for_function(f"window.pairplay.state.cards[{card}].state !== 'down'")
                        faces[card] = board.evaluate(f"window.pairplay.state.cards[{card}].face")
                        return
                    board.wait_for_function(f"window.pairplay.state.last_turn && window.pairplay.state.last_turn.id > {turns}")
                    last = board.evaluate("window.pairplay.state.last_turn")
                    faces.update(zip(last["cards"], last["faces"]))

                while board.evaluate("window.pairplay.state.matches") < 3:  # a player with a good memory
                    down = board.evaluate("window.pairplay.state.cards.map((c, i) => c.state === 'down' ? i : -1)"
                                          ".filter(i => i >= 0)")
                    pair = next(((a, b) for a in down for b in down if a < b and a in faces and b in faces
                                 and faces[a] == faces[b]), None)
                    if pair:
                        click(pair[0])
                        click(pair[1], second=True)
                        continue
                    first = next(c for c in down if c not in faces)
                    click(first)
                    mate = next((c for c in down if c != first and faces.get(c) == faces[first]), None)
                    click(mate if mate is not None else next(c for c in down if c not in faces and c != first), True)
                down = board.evaluate("window.pairplay.state.cards.map((c, i) => c.state === 'down' ? i : -1)"
                                      ".filter(i => i >= 0)")
                click(down[len(down) // 2])
                for _ in range(12):  # a suggestion with a visual part that points somewhere
                    mirror.wait_for_function("window.pairplay.state.suggestion && window.pairplay.state.robot.length")
                    s = mirror.evaluate("window.pairplay.state.suggestion")
                    if s["parts"]["head"] not in ("head still", "nod") and len(s["seen"]) >= 2 \
                            and s["parts"]["speech"] != "say nothing":
                        break
                    attempt = s["attempt"]
                    board.click("#wrong")
                    mirror.wait_for_function(f"window.pairplay.state.suggestion && "
                                             f"window.pairplay.state.suggestion.attempt > {attempt}")
                # the robot finished this suggestion: the mirror's table shows when
                mirror.wait_for_function("""(() => { const s = window.pairplay.state, g = s.suggestion;
                    return s.robot.some(r => r.turn === s.turn && r.attempt === g.attempt && r.outcome === 'done'); })()""",
                                         timeout=10000)
                board.wait_for_timeout(300)
                board.screenshot(path=str(out / "lab-board.png"))
                mirror.screenshot(path=str(out / "lab-mirror.png"))
                browser.close()
        finally:
            stop.set()
            t.join(30)


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "docs"))
