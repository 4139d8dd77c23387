"""Bench: a touch on the board page -> SuggestionMade -> robot command, beside the raw WebSocket round trip.

Rule: a whole lab session (game, learner, virtual robot, web server) runs in
this process; Debian's headless Chromium plays it by mouse clicks on the
board page (Playwright, never a downloaded browser). For the first pick of
each turn the latency runs from the click event's time on the page's clock
(CardPicked.page_time_ms: performance.timeOrigin + event.timeStamp) to the
learner's SuggestionMade (its envelope time) and to the robot bridge's first
command written (RobotActed.sent_ns, the virtual robot). Page and server
clocks are both this machine's wall clock; their offset is measured in the
same run from the ping with the smallest round trip (NTP-style, error within
half that round trip) and taken out. The reference is the raw WebSocket
round trip page -> server -> page (a ping the hub answers at once), measured
once a turn between the same turns, so both see the same idle and load.
"""

from __future__ import annotations

import tempfile
import threading
from pathlib import Path

import numpy as np

from pairplay.replay.reader import read_log
from pairplay.schemas.config import LearnerConfig
from pairplay.schemas.session import SessionConfig, learner_overrides

CHROMIUM = Path("/usr/bin/chromium")
ARGS = ["--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--disable-background-networking",
        "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-extensions"]


def _play(page, turns: int) -> list[dict]:
    """Play `turns` turns by clicks (first two covered cards each time); one ping per turn."""
    boxes = {i: page.locator(f"[data-card='{i}']").bounding_box() for i in range(18)}
    centers = {i: (b["x"] + b["width"] / 2, b["y"] + b["height"] / 2) for i, b in boxes.items()}
    pings = []
    for _ in range(turns):
        for pick in range(2):
            page.wait_for_function("window.pairplay.canTouch() && window.pairplay.state.phase === "
                                   + ("'first'" if pick == 0 else "'second'"), timeout=10000, polling=5)
            down = page.evaluate("window.pairplay.state.cards.map((c, i) => c.state === 'down' ? i : -1)"
                                 ".filter(i => i >= 0)")
            page.mouse.click(*centers[down[0]])
        page.wait_for_timeout(5)
        pings.append(page.evaluate("""async () => { const p = await window.pairplay.link.ping();
                                       return {rtt: p.rtt, sent: performance.timeOrigin + p.sent,
                                               server_ms: p.server_ns / 1e6}; }"""))
    return pings


NOT_MEASURED = "lab: touch -> SuggestionMade -> robot command: not measured, "


def bench_rows(quick: bool = False) -> list[dict]:
    try:  # playwright is in the [test] and [picture] extras, not the quick start's install
        from playwright.sync_api import sync_playwright
    except ModuleNotFoundError as err:
        return [{"row": f"{NOT_MEASURED}{(err.name or 'playwright').split('.')[0]} is not installed (pip install -e '.[test]'; no browser "
                        "is downloaded)", "value": None, "unit": "ms"}]
    if not CHROMIUM.exists():
        return [{"row": f"{NOT_MEASURED}{CHROMIUM} is absent (apt-get install chromium)", "value": None, "unit": "ms"}]

    from pairplay.services.lab.server import run_lab

    turns = 60 if quick else 200
    config = SessionConfig(session="bench-lab", participant="human:bench", seed=0, rounds=100,
                           observed_source="first-pick", ignore_rule="time", ignore_clock="page",
                           ignore_window_ms=0.0, turn_back_ms=0.0,
                           learner=learner_overrides(LearnerConfig.human_phase1(100)))
    with tempfile.TemporaryDirectory(prefix="pairplay-bench-lab-") as tmp:
        ready, stop, box = threading.Event(), threading.Event(), {}

        def on_ready(urls, bus):
            box["urls"] = urls
            ready.set()

        t = threading.Thread(target=lambda: box.setdefault("path", run_lab(
            config, Path(tmp) / "bench-lab.mcap", stop=stop, on_ready=on_ready, linger_s=0.0)), daemon=True)
        t.start()
        ready.wait(30)
        try:
            with sync_playwright() as pw:
                browser = pw.chromium.launch(executable_path=str(CHROMIUM), args=ARGS, headless=True)
                page = browser.new_context(viewport={"width": 1024, "height": 600}, bypass_csp=True).new_page()
                page.goto(box["urls"].board)
                page.wait_for_function("window.pairplay && window.pairplay.state && window.pairplay.canTouch()",
                                       timeout=20000)
                _play(page, 10)  # warm-up
                pings = _play(page, turns)
                browser.close()
        finally:
            stop.set()
            t.join(60)
        events = [r.event for r in read_log(box["path"]).events]
    best = min(pings, key=lambda p: p["rtt"])
    offset_ms = best["server_ms"] - (best["sent"] + best["rtt"] / 2)  # server clock - page clock
    first = {}
    for e in events:  # the first pick of each turn: the touch the suggestion answers
        if type(e).__name__ == "CardPicked" and e.source == "board":
            first.setdefault((e.round, e.turn), e.page_time_ms + offset_ms)
    took = {}
    for e in events:
        if type(e).__name__ == "CardPicked" and e.source == "board":
            took.setdefault((e.round, e.turn), e.time_ns / 1e6)
    made = {(e.round, e.turn): e.time_ns / 1e6 for e in events if type(e).__name__ == "SuggestionMade"}
    acted = {(e.round, e.turn): e.sent_ns / 1e6 for e in events if type(e).__name__ == "RobotActed" and e.sent_ns}
    keys = sorted(k for k in made if k in first and k in acted)[10:]  # past the warm-up turns
    to_server = np.array([took[k] - first[k] for k in keys])
    to_made = np.array([made[k] - first[k] for k in keys])
    to_robot = np.array([acted[k] - first[k] for k in keys])
    rtt = np.array([p["rtt"] for p in pings])
    rows = []
    for q in (50, 99):
        reference = float(np.percentile(rtt, q))
        for name, values in (("the server took it (context)", to_server), ("SuggestionMade", to_made),
                             ("robot command sent (virtual robot)", to_robot)):
            value = float(np.percentile(values, q))
            rows.append({"row": f"lab: touch on the page -> {name}, p{q} ({len(values)} turns)", "value": value,
                         "unit": "ms", "reference": f"raw WebSocket round trip page -> server -> page, p{q} "
                                                    f"(clock offset {offset_ms:+.2f} ms taken out, +-{best['rtt'] / 2:.2f})",
                         "reference_value": reference, "ratio": value / reference})  # no goal set yet: context
    return rows


if __name__ == "__main__":
    for row in bench_rows(quick=True):
        print(row)
