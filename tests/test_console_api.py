"""The console's web API over real HTTP: the token, malformed requests, refused steps, questionnaire answers."""

from __future__ import annotations

import json
import urllib.error
import urllib.request
from pathlib import Path

import pytest

from pairplay.replay.studydata import StudyData, StudyDataError
from pairplay.schemas.study import parse_study
from pairplay.services.bus import Bus, BusOptions
from pairplay.services.console.server import ConsoleServer
from pairplay.services.protocol import StudyRunner, check_answers

STUDY = Path(__file__).parent / "data" / "pilot-study.toml"


def call(url: str, body=None, raw: bytes | None = None) -> tuple[int, dict]:
    data = raw if raw is not None else (None if body is None else json.dumps(body).encode())
    req = urllib.request.Request(url, data=data, method="POST" if data is not None else "GET",
                                 headers={"content-type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as err:
        text = err.read()
        try:
            return err.code, json.loads(text)
        except ValueError:
            raise AssertionError(f"{url}: HTTP {err.code} {text[:200]!r}") from None


@pytest.fixture
def lab(tmp_path):
    data = StudyData.create(tmp_path / "study", STUDY)
    with Bus(BusOptions()) as bus:
        server = ConsoleServer(StudyRunner(data, bus)).start()
        try:
            yield server, data
        finally:
            server.close()


def test_the_api_needs_the_experimenter_token(lab):
    server, _ = lab
    assert server.url.startswith("http://127.0.0.1:")  # loopback unless told otherwise
    for token in ("", "wrong", server.token[:-1]):
        status, body = call(f"{server.url}/api/console/state?token={token}")
        assert status == 403 and "token" in body["error"]
    status, body = call(f"{server.url}/api/console/register?token=nope", {"phase": "phase1"})
    assert status == 403
    status, body = call(f"{server.url}/api/console/state?token={server.token}")
    assert status == 200 and body["study"]["id"] == "pilot" and body["next"] is None  # nobody registered yet


def test_malformed_and_refused_requests_get_one_line(lab):
    server, data = lab
    t = server.token
    cases = [
        ("register", None, b"{not json"),
        ("register", ["phase1"], None),
        ("register", {"phase": "phase9"}, None),
        ("register", {"phase": "phase1", "count": "many"}, None),
        ("register", {"phase": "phase1", "label": "A Name"}, None),  # no key file: no names
        ("next", {}, None),
        ("control/abort", {"reason": "x"}, None),
        ("control/pause", {}, None),
        ("control/invalid", {"session": "nope", "reason": "x"}, None),
        ("control/explode", {}, None),
        ("delete", {"participant": "p01", "confirm": "p01"}, None),
        ("export", {"participant": 7}, None),
        ("register", None, b"x" * 70000),  # above 64 KiB: 413, before the route (tests/test_body_limit.py)
    ]
    for path, body, raw in cases:
        status, answer = call(f"{server.url}/api/console/{path}?token={t}", body, raw)
        assert status == (413 if raw and len(raw) > 65536 else 400), (path, status)
        assert "\n" not in answer["error"] and answer["error"], (path, answer)
    assert data.state.participants == {}


def test_a_request_the_command_line_refuses_is_refused_by_the_console_in_the_same_words(lab):
    """trial15: the console registered two participants under one name (`count` 2 with a `label`), which
    `protocol register --name X --count 2` refuses; took an unknown key silently; and said "count must be
    1..50" of the text "2". Every request body is now read as a Struct that refuses unknown keys, and the
    register and mark-invalid rules are StudyData's, shared with the command line."""
    server, data = lab
    t = server.token
    cases = [
        ({"phase": "phase1", "count": 2, "label": "Anna"}, "a name (`label`) registers one participant: leave out `count`"),
        ({"phase": "phase1", "count": "2"}, "count: must be an integer, got text"),
        ({"phase": "phase1", "count": 0}, "`count` must be a whole number 1..50, got 0"),
        ({"phase": "phase1", "extra": 1}, "no key `extra` is known here; the keys: consent, count, label, phase"),
        ({"phase": "phase1", "lable": "Anna"}, "no key `lable` is known here (did you mean `label`?)"),
        # a newline became a space in the key file without a word (a new user's trial): refused as the CLI does
        ({"phase": "phase1", "label": 'Bob\n,evil"'}, "a name (`label`) holds a control character ('\\n' at 3): "
                                                     "give the name as one line of text, without tabs"),
    ]
    for body, said in cases:
        status, answer = call(f"{server.url}/api/console/register?token={t}", body)
        assert (status, answer["error"]) == (400, said), body
    for body, said in [({"session": "nope", "reason": " "}, "marking a session invalid needs a reason"),
                       ({"session": "nope", "reason": "x", "why": "y"}, "no key `why` is known here; the keys: reason, session")]:
        status, answer = call(f"{server.url}/api/console/control/invalid?token={t}", body)
        assert (status, answer["error"]) == (400, said), body
    assert data.state.participants == {} and not data.read_journal()[1:]  # nothing registered, nothing journaled
    status, answer = call(f"{server.url}/api/console/register?token={t}", {"phase": "phase1", "count": 2})
    assert status == 200 and answer["registered"] == ["p01", "p02"]
    status, answer = call(f"{server.url}/api/console/delete?token={t}", {"participant": "p01", "confirm": "p02"})
    assert status == 400 and "confirm" in answer["error"]
    status, answer = call(f"{server.url}/api/questionnaire?session=x&token=y")
    assert status == 403
    # the answer needs the link's token too, before its body is read (trial28 F13: it took any body from anyone)
    status, answer = call(f"{server.url}/api/questionnaire/answer", {"session": "x", "token": "", "answers": {}})
    assert status == 403 and "not the current game" in answer["error"]
    for name in ("..%2Fjournal.jsonl", "journal.jsonl", "p01.zip"):
        with pytest.raises(urllib.error.HTTPError) as err:
            urllib.request.urlopen(f"{server.url}/api/console/exports/{name}?token={t}", timeout=10)
        assert err.value.code == 404


def test_answers_are_checked_against_the_items():
    study = parse_study(STUDY.read_text())
    items = study.questions("after-game", returning=False)
    good = {"followed": "4", "avoided-wrong": 5, "speech": "3", "visual": "2", "gaze": "1",
            "contradictory": "followed the speech", "robots-before": "no"}
    assert check_answers(items, good)["avoided-wrong"] == "5"
    for bad, why in [({**good, "followed": "6"}, "1..5"), ({**good, "followed": True}, "text or a number"),
                     ({**good, "contradictory": "shrugged"}, "not one of"), ({**good, "best-round": "1"}, "no question"),
                     ({k: v for k, v in good.items() if k != "gaze"}, "needs an answer"),
                     ({**good, "comments": "x" * 2001}, "at most"), ([1, 2], "object"),
                     # a digit that is not ASCII ('²': int() raised ValueError, a 500), a number past int()'s limit
                     ({**good, "followed": "\u00b2"}, "1..5"), ({**good, "followed": "9" * 5000}, "1..5"),
                     ({**good, "followed": 10**30}, "1..5")]:
        with pytest.raises(StudyDataError, match=why):
            check_answers(items, bad)


def test_a_game_that_fails_to_start_is_journaled_ended_and_the_console_says_why(tmp_path):
    """Before: a robot URL the bridge refuses (a study file checked by an older pairplay, or a runner given
    one) made POST next say "started", logged a traceback, and left a GameStarted without an end in the
    journal (the console showed the game running for ever)."""
    import time

    from pairplay.services.robot.choice import RobotChoice

    data = StudyData.create(tmp_path / "study", STUDY)
    with Bus(BusOptions()) as bus:
        server = ConsoleServer(StudyRunner(data, bus, robot=RobotChoice("furhat://"))).start()
        try:
            t = server.token
            call(f"{server.url}/api/console/register?token={t}", {"phase": "phase1", "count": 2, "consent": True})
            status, answer = call(f"{server.url}/api/console/next?token={t}", {})
            assert status == 200, answer
            deadline = time.monotonic() + 20
            while True:
                _, state = call(f"{server.url}/api/console/state?token={t}")
                if not state["busy"] or time.monotonic() > deadline:
                    break
                time.sleep(0.05)
        finally:
            server.close()
    assert not state["busy"] and not state["last"]["ok"], state["last"]
    assert "needs a host" in state["last"]["message"] and "\n" not in state["last"]["message"]
    [game] = state["games"]
    assert game["outcome"] == "aborted" and "the game failed" in game["reason"] and "needs a host" in game["reason"]
    journal = [json.loads(line) for line in (tmp_path / "study" / "journal.jsonl").read_text().splitlines()]
    started = {e["session"] for e in journal if e["event"] == "GameStarted"}
    ended = {e["session"] for e in journal if e["event"] == "GameEnded"}
    assert started and started == ended, journal
    assert state["next"]["label"] and not state["next"]["done"]  # the same game again, as a retry


def test_an_empty_study_says_to_register_participants_first(lab, pairplay_cli):
    """Before: "[blocked] combine the policies ... (the games of phase1 are not all played)", in the
    console and `protocol status`, of a study nobody was registered in (a new user's trial)."""
    server, data = lab
    _, state = call(f"{server.url}/api/console/state?token={server.token}")
    assert state["next"] is None, state["next"]  # no step: registering comes first (trial27 F12a)
    assert "register its participants first" in state["plan"][0]["blocked"], state["plan"]  # (the combination)
    assert "not all played" not in state["plan"][0]["blocked"]
    status, answer = call(f"{server.url}/api/console/next?token={server.token}", {})
    assert status == 400 and answer["error"] == "nobody is registered: register participants first", answer
    r = pairplay_cli("protocol", "status", data.folder)
    assert r.returncode == 0 and "not all played" not in r.stdout, r.stdout
    assert r.stdout.splitlines()[0] == f"nobody is registered: `pairplay protocol register {data.folder}` first"
    assert "register its participants first" in r.stdout
    data.register("phase1")
    _, state = call(f"{server.url}/api/console/state?token={server.token}")
    assert state["plan"][2]["kind"] == "combine" and "register another participant" in state["plan"][2]["blocked"]
