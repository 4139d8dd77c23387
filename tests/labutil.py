"""Helpers for tests of the lab: a whole lab session in a thread, its pages in the module's browser."""

from __future__ import annotations

import queue
import threading
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

from pairplay.schemas.config import LearnerConfig
from pairplay.schemas.session import SessionConfig, learner_overrides
from pairplay.services.bus import Bus
from pairplay.services.lab.server import LabUrls, run_lab


def human_config(session: str, rounds: int = 1, **fields) -> SessionConfig:
    fields.setdefault("observed_source", "first-pick")
    fields.setdefault("ignore_rule", "time")
    fields.setdefault("ignore_clock", "page")
    fields.setdefault("turn_back_ms", 30.0)
    return SessionConfig(session=session, participant="human:p01", seed=3, rounds=rounds,
                         learner=learner_overrides(LearnerConfig.human_phase1(rounds)), **fields)


@dataclass
class RunningLab:
    config: SessionConfig
    urls: LabUrls
    bus: Bus
    path: Path
    stop: threading.Event
    thread: threading.Thread
    nodes: dict = field(default_factory=dict)
    result: dict = field(default_factory=dict)

    def wait(self, timeout_s: float = 60.0) -> Path:
        self.thread.join(timeout_s)
        assert not self.thread.is_alive(), "the lab session did not end"
        return self.result["path"]


@contextmanager
def running_lab(tmp_path: Path, config: SessionConfig, before_start=None):
    """Run `config` as a lab session (virtual robot) until the block ends (then stop it)."""
    ready: queue.Queue = queue.Queue()
    stop = threading.Event()
    nodes: dict = {}
    result: dict = {}
    path = tmp_path / f"{config.session}.mcap"

    def on_ready(urls, bus):
        if before_start is not None:
            before_start(bus)
        ready.put((urls, bus))

    def target():
        try:
            result["path"] = run_lab(config, path, stop=stop, on_ready=on_ready, linger_s=0.0, nodes_out=nodes)
        except BaseException as err:  # surfaced by the test through `result`
            result["error"] = err
            ready.put(None)

    t = threading.Thread(target=target, daemon=True)
    t.start()
    got = ready.get(timeout=30)
    assert got is not None, result.get("error")
    lab = RunningLab(config, got[0], got[1], path, stop, t, nodes, result)
    try:
        yield lab
    finally:
        stop.set()
        t.join(30)


def open_page(browser, url: str, width: int = 1024, height: int = 600):
    """A page in its own context (its own sessionStorage: another tab of another person)."""
    ctx = browser.new_context(viewport={"width": width, "height": height}, bypass_csp=True)  # CSP: evaluate()
    page = ctx.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.errors = errors
    logged: list[str] = []  # what the page logs as an error (a failed fetch's 404 is one, not a page error)
    page.on("console", lambda m: logged.append(m.text) if m.type == "error" else None)
    page.console_errors = logged
    page.goto(url)
    page.wait_for_function("window.pairplay && window.pairplay.state !== null", timeout=15000)
    return page


def card_centers(page) -> dict:
    """card -> (x, y), the centre of each card on the page in viewport pixels (what `page.mouse.click`
    takes): one evaluate for the 18 cards, not a locator round trip each."""
    rects = page.evaluate("""() => Array.from({length: 18}, (_, i) => {
        const r = document.querySelector(`[data-card='${i}']`).getBoundingClientRect();
        return [r.x + r.width / 2, r.y + r.height / 2]; })""")
    return {i: tuple(c) for i, c in enumerate(rects)}


def wait_phase(page, *phases: str, timeout_ms: int = 10000) -> None:
    page.wait_for_function(f"window.pairplay.state && {list(phases)!r}.includes(window.pairplay.state.phase)",
                           timeout=timeout_ms)
