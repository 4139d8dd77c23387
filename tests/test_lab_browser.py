"""The lab's pages in a real headless Chromium (one per module): a person plays.

A whole game is played by clicks, a `core` persona choosing each card; the
recording then passes `pairplay replay --verify` and `pairplay rebuild`. The
wrong-suggestion button, a reload mid-turn, two tabs, bad and stale WebSocket
messages, a wrong token, the mirror, an eye tracker, a 1024 x 600 screen.
"""

from __future__ import annotations

import json
import queue

import msgspec

from labutil import card_centers, human_config, open_page, running_lab, wait_phase
from pairplay.replay.reader import read_log
from pairplay.schemas import events as ev
from pairplay.schemas.envelope import stamped
from pairplay.schemas.events import decode_event, encode_event
from pairplay.schemas.keys import alive_key, event_key, session_keys
from pairplay.services.node import Driver
from pairplay.services.participant import ParticipantLogic


def recorded(path):
    return [r.event for r in read_log(path).events]


def of(events, tag, source=None):
    return [e for e in events if type(e).__name__ == tag and (source is None or e.source == source)]


def click_when_ready(page, card: int, centers: dict | None = None, at: tuple[int, int] | None = None) -> None:
    """Click `card` once the page takes touches (at round, turn `at`: as a person, the script
    waits until the board shows the turn); with `centers` (card -> (x, y)), a plain mouse
    click at its centre (real input events, without the locator's waits: a game is 150 clicks)."""
    here = f"window.pairplay.state.round === {at[0]} && window.pairplay.state.turn === {at[1]} && " if at else ""
    page.wait_for_function(here + "window.pairplay.canTouch()", timeout=10000, polling=5)
    if centers is None:
        page.click(f"[data-card='{card}']")
    else:
        page.mouse.click(*centers[card])


def test_a_whole_game_played_by_clicks_verifies_and_rebuilds(browser, tmp_path, pairplay_cli):
    """Two rounds (a new board and the learner's next epsilon: every per-turn and per-round check of a
    5-round game, at 2/5 of its clicks; the thesis's 5 rounds are played by clicks in test_console_browser's
    slow variant); persona Tatiana (core.user) decides every card, the script clicks it."""
    rounds = 2
    config = human_config("lab-game", rounds=rounds, ignore_window_ms=0.0)  # clicks are fast: learn from every turn
    inbox: queue.Queue = queue.Queue()
    with running_lab(tmp_path, config,
                     before_start=lambda bus: bus.subscribe(session_keys("lab-game"),
                                                            lambda k, p: inbox.put((k, p)))) as lab:
        page = open_page(browser, lab.urls.board)
        # the persona plays through the page: it reads what the game and the learner say on the bus
        centers = card_centers(page)
        persona = Driver(ParticipantLogic(), config.session, clock=lambda: 0)
        clicked = []
        while not persona.logic.done:
            key, payload = inbox.get(timeout=20)
            event = decode_event(payload)
            if isinstance(event, ev.SessionStarted):  # the persona plays the person's part
                sim = msgspec.structs.replace(event.config, participant="sim:tatiana", persona="tatiana")
                payload = encode_event(msgspec.structs.replace(event, config=sim))
            for out in persona.receive(key, payload):
                if isinstance(out, ev.CardPicked):
                    click_when_ready(page, out.card, centers, at=(out.round, out.turn))
                    clicked.append(out.card)
        wait_phase(page, "over")
        # `pairplay lab` has no questionnaire: the board asks for none (trial27 F12: it fetched the study's
        # route and logged a 404 at the end of every lab game)
        assert not page.evaluate("window.pairplay.askedQuestionnaire")
        assert page.errors == [] and page.console_errors == []
        path = lab.wait()
    events = recorded(path)
    picks = of(events, "CardPicked", "board")
    assert [p.card for p in picks] == clicked and len(of(events, "RoundEnded")) == rounds
    assert all(p.page_time_ms > 0 for p in picks)  # the page's clock, beside the server's envelope time
    turns = of(events, "TurnResolved")
    assert all(t.page_interval_ms > 0 and t.interval_ms > 0 for t in turns)
    assert len(of(events, "RewardGiven")) == len(of(events, "SuggestionMade")) and of(events, "QUpdated")
    assert len(of(events, "RobotActed")) == len(of(events, "SuggestionMade"))  # the virtual robot acted on each
    assert not of(events, "PickRejected") and not of(events, "MessageRejected")
    run = pairplay_cli
    r = run("replay", str(path), "--verify")
    assert r.returncode == 0 and "verify: PASS" in r.stdout, r.stdout + r.stderr
    r = run("rebuild", str(path), "--out", str(tmp_path / "rebuilt"))
    assert r.returncode == 0, r.stdout + r.stderr
    assert json.loads((tmp_path / "rebuilt" / "lab-game.policy.json").read_text())["participant"] == "human:p01"


def test_wrong_suggestion_reload_two_tabs_and_bad_messages(browser, tmp_path):
    config = human_config("lab-ui", rounds=1)  # the 1.5 s window, on the page's clock
    with running_lab(tmp_path, config) as lab:
        page = open_page(browser, lab.urls.board)
        assert page.evaluate("window.pairplay.role") == "player"
        wait_phase(page, "first")
        page.click("[data-card='0']")
        wait_phase(page, "second")
        assert page.get_attribute("[data-card='0']", "class").split() == ["card", "up", "observed"]
        # the wrong-suggestion button: -3 for the open suggestion and a new one in the same turn
        assert page.is_enabled("#wrong")
        page.click("#wrong")
        page.wait_for_function("window.pairplay.state.attempt === 1")
        # a reload mid-turn resumes from the server's state, with the same role
        page.reload()
        page.wait_for_function("window.pairplay.state && window.pairplay.state.attempt === 1")
        state = page.evaluate("window.pairplay.state")
        assert state["phase"] == "second" and state["cards"][0]["state"] == "up" and state["observed"] == 0
        assert page.evaluate("window.pairplay.role") == "player"
        assert all(c["face"] == -1 for c in state["cards"][1:])  # no covered face reaches the page
        # a second tab on the same session is read-only
        other = open_page(browser, lab.urls.board)
        assert other.evaluate("window.pairplay.role") == "viewer"
        assert other.locator("#wrong").is_hidden()
        other.evaluate("window.pairplay.link.send({type: 'pick', id: 1, round: 0, turn: 0, card: 5, page_ms: 1})")
        other.wait_for_function("window.pairplay.state && window.pairplay.state.cards[5].state === 'down'")
        # bad and stale messages from the playing page: refused, told, recorded
        bad = page.evaluate("""() => { const id = () => window.pairplay.nextId(), s = JSON.stringify;
            const msgs = ["{not json", s({type: "teleport"}), s({type: "pick", id: id()}),
              s({type: "pick", id: id(), round: 0, turn: 7, card: 3, page_ms: 1}),
              s({type: "wrong", id: id(), round: 0, turn: 0, attempt: 0, page_ms: 1}),
              s({type: "pick", id: id(), round: 0, turn: 0, card: 99, page_ms: 1}),
              s({type: "pick", id: 1, round: 0, turn: 0, card: 3, page_ms: 1}), "x".repeat(5000)];
            msgs.forEach(m => window.pairplay.link.ws.send(m)); return msgs; }""")
        page.evaluate("window.pairplay.link.ws.send(new Uint8Array([1, 2, 3]))")
        page.wait_for_function(f"window.pairplay.rejected.length >= {len(bad) + 1}")
        reasons = [r["reason"] for r in page.evaluate("window.pairplay.rejected")]
        assert "malformed" in reasons[0] and "malformed" in reasons[1] and "malformed" in reasons[2]
        assert "stale" in reasons[3] and "stale" in reasons[4] and "not on the board" in reasons[5]
        assert reasons[3].startswith("stale: for round 1, turn 8, but the game is in round 1, turn "), reasons[3]
        assert "not above" in reasons[6] and "at most 4096" in reasons[7] and "binary" in reasons[8]
        # a lost connection: the page reconnects by itself and gets the whole view again
        page.evaluate("window.pairplay.link.ws.close()")
        page.wait_for_function("window.pairplay.link.connects === 2 && window.pairplay.link.open")
        page.wait_for_function("window.pairplay.role === 'player' && window.pairplay.state.attempt === 1")
        # the game goes on: the second pick, then the turn resolves
        second = page.evaluate("window.pairplay.state.cards.findIndex((c, i) => i > 0 && c.state === 'down')")
        click_when_ready(page, second)
        page.wait_for_function("window.pairplay.state.turn === 1")
        # the player's tab goes away: the read-only one takes over
        page.context.close()
        other.wait_for_function("window.pairplay.role === 'player'", timeout=15000)  # after LabHub.SEAT_KEPT_S
        assert other.errors == []
        lab.stop.set()
        path = lab.wait()
    events = recorded(path)
    rewards = of(events, "RewardGiven")
    assert rewards[0].reward == -3.0 and rewards[0].attempt == 0 and rewards[0].reason == "wrong suggestion pressed"
    assert [s.attempt for s in of(events, "SuggestionMade")][:2] == [0, 1]
    assert of(events, "WrongSuggestionPressed", "board")[0].attempt == 0
    turn = of(events, "TurnResolved")[0]  # timed on the page's clock: the reload took a while
    assert turn.ignored_by_time == (turn.page_interval_ms < 1500) == (not rewards[1].learned)
    refused = of(events, "MessageRejected", "board")
    assert len(refused) >= len(bad) + 2  # the read-only page's pick too
    assert any("read-only" in r.reason for r in refused) and all(r.key.startswith("ws/lab-ui/") for r in refused)


def test_a_wrong_token_gets_nothing_and_is_recorded(browser, tmp_path):
    with running_lab(tmp_path, human_config("lab-token")) as lab:
        base = lab.urls.board.split("?")[0]
        ctx = browser.new_context()
        page = ctx.new_page()
        assert page.goto(base + "?t=guess").status == 403
        assert page.goto(base.replace("lab-token", "other") + "?t=" + lab.urls.board.split("t=")[1]).status == 403
        page.goto(lab.urls.board.split("/s/")[0] + "/static/board.html")
        ws_url = lab.urls.board.replace("http", "ws").replace("/board?t=", "/ws?page=board&client=x&t=") + "x"
        closed = page.evaluate("""url => new Promise(done => { const ws = new WebSocket(url);
                                  ws.onclose = e => done(e.code); ws.onmessage = () => done('message'); })""", ws_url)
        assert closed != "message"
        ctx.close()
        lab.stop.set()
        path = lab.wait()
    assert any("wrong token" in r.reason for r in of(recorded(path), "MessageRejected", "board"))


def test_the_board_fits_1024x600_with_its_own_content_security_policy(browser, tmp_path):
    with running_lab(tmp_path, human_config("lab-small")) as lab:
        for width, height in ((1024, 600), (1920, 1080)):
            ctx = browser.new_context(viewport={"width": width, "height": height}, has_touch=True)
            page = ctx.new_page()  # no CSP bypass: the page must work under its own policy
            errors = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.on("console", lambda m: errors.append(m.text) if "Content Security Policy" in m.text else None)
            page.goto(lab.urls.board)
            page.locator("body[data-phase='first'], body[data-phase='second']").wait_for(state="attached", timeout=10000)
            boxes = [page.locator(f"[data-card='{i}']").bounding_box() for i in range(18)]
            assert all(b["width"] >= 0.12 * width and b["height"] >= 100 for b in boxes)  # big touch targets
            assert all(b["x"] >= 0 and b["y"] >= 0 and b["x"] + b["width"] <= width and b["y"] + b["height"] <= height
                       for b in boxes)  # no scrolling
            if width == 1024:  # the player's page (the next one is read-only for a moment: the seat is kept)
                wrong = page.locator("#wrong").bounding_box()
                assert wrong["height"] >= 40 and wrong["y"] + wrong["height"] <= boxes[0]["y"]  # above the cards
                page.tap("[data-card='4']")  # a touch, not a click
                page.locator("[data-card='4'][data-state='up']").wait_for(timeout=5000)
            assert errors == []
            ctx.close()


def test_the_mirror_shows_the_suggestion_and_the_robot(browser, tmp_path):
    """... and the ignore rule times the picks on the page's clock (a 5 s window here)."""
    with running_lab(tmp_path, human_config("lab-mirror", ignore_window_ms=5000.0)) as lab:
        page = open_page(browser, lab.urls.board)
        mirror = open_page(browser, lab.urls.mirror)
        wait_phase(page, "first")
        page.click("[data-card='7']")
        mirror.wait_for_function("window.pairplay.state.suggestion && window.pairplay.state.robot.length > 0")
        s = mirror.evaluate("window.pairplay.state")
        sug = s["suggestion"]
        assert sug["observed"] == 7 and "target" not in sug and s["robot"][0]["backend"] == "virtual"
        assert mirror.inner_text("#speech").strip() != "…" and "virtual" in mirror.inner_text("#robot")
        # the visual part's region is highlighted (and an arrow drawn) when there is one
        highlighted = mirror.locator(".card.region").count()
        visual = not (sug["parts"]["head"] == "head still" and sug["parts"]["gaze"] == "no gaze")
        assert highlighted == (len(sug["seen"]) if visual else 0)
        # the mirror is read-only
        mirror.evaluate("window.pairplay.link.send({type: 'pick', id: 1, round: 0, turn: 0, card: 3, page_ms: 1})")
        page.wait_for_timeout(200)
        assert page.evaluate("window.pairplay.state.cards[3].state") == "down"
        assert mirror.errors == [] and page.errors == []
        # the page says 6 s passed between its picks; the server saw less than the 5 s window
        page.evaluate("""window.pairplay.link.send({type: 'pick', id: window.pairplay.nextId(), round: 0, turn: 0,
                         card: 3, page_ms: performance.timeOrigin + performance.now() + 6000})""")
        page.wait_for_function("window.pairplay.state.turn === 1")
        lab.stop.set()
        path = lab.wait()
    turn = of(recorded(path), "TurnResolved")[0]
    assert turn.page_interval_ms >= 6000 and turn.interval_ms < 5000 and not turn.ignored_by_time


def test_an_eye_tracker_gives_the_observed_card(browser, tmp_path):
    """Observed source 'gaze': a simulated tracker publishes GazeFixated; the board highlights it."""
    config = human_config("lab-gaze", observed_source="gaze")
    tracker = {"seq": 0}

    def fixate(bus, card):
        tracker["seq"] += 1
        e = stamped(ev.GazeFixated(card=card, duration_ms=200.0), session="lab-gaze", source="tracker",
                    seq=tracker["seq"], time_ns=__import__("time").time_ns())
        bus.put(event_key("lab-gaze", "tracker", "GazeFixated"), encode_event(e))

    with running_lab(tmp_path, config, before_start=lambda bus: bus.alive(alive_key("lab-gaze", "tracker"))) as lab:
        page = open_page(browser, lab.urls.board)
        wait_phase(page, "first")
        page.click("[data-card='2']")
        wait_phase(page, "looking")  # no fixation yet: no suggestion
        fixate(lab.bus, 2)  # the first card itself: not an observation of the second
        fixate(lab.bus, 11)
        wait_phase(page, "second")
        assert page.evaluate("window.pairplay.state.observed") == 11
        assert "observed" in page.get_attribute("[data-card='11']", "class")
        lab.stop.set()
        path = lab.wait()
    observed = of(recorded(path), "CardObserved")
    assert [(o.card, o.observed_source) for o in observed] == [(11, "gaze")]
