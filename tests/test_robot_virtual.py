"""The virtual robot: the default backend, so a session runs with no hardware."""

from __future__ import annotations

import json

import pytest

from robot_doubles.harness import FAMILIES, FAST, Collector, suggestion

from pairplay.core.actions import code_of_parts
from pairplay.services.robot import open_robot


def robot(collector: Collector, url: str = "virtual?time_scale=0"):
    return open_robot(url, collector.on_acted, config=FAST, on_rejected=collector.on_rejected)


def test_every_family_is_performed_and_reported():
    collector = Collector()
    driver = robot(collector)
    try:
        for seq, code in enumerate(FAMILIES.values()):
            driver.perform(suggestion(code, seq=seq))
            assert driver.wait_idle(5)
    finally:
        driver.close()
    outcomes = {a.suggestion_seq: a.outcome for a in collector.acted}
    assert outcomes == {0: "done", 1: "done", 2: "done", 3: "done", 4: "sent", 5: "sent"}
    assert all(a.backend == "virtual" for a in collector.acted)
    performed = [json.loads(text) for _, text in driver.transport.performed]
    assert [p["type"] for p in performed][:3] == ["say", "say", "gesture"]
    assert performed[0]["text"] == "Try at row 2 and column 5"


def test_a_newer_suggestion_cuts_the_virtual_speech_short():
    collector = Collector()
    driver = robot(collector, "virtual")  # real speech durations: still speaking at the next one
    try:
        driver.perform(suggestion(code_of_parts(2, 0, 0, 0), seq=1))
        driver.perform(suggestion(code_of_parts(0, 1, 0, 0), seq=2))
        assert collector.wait_for(lambda c: 1 in c.by_seq())
    finally:
        driver.close()
    first = collector.by_seq()[1]
    assert first.outcome == "aborted" and first.replies[-1] == "speech.end (aborted)"
    assert [json.loads(t)["type"] for _, t in driver.transport.performed] == ["say", "stop_speech", "gesture"]


def test_do_nothing_sends_nothing():
    collector = Collector()
    driver = robot(collector)
    try:
        driver.perform(suggestion(0))
        assert driver.wait_idle(5)
    finally:
        driver.close()
    assert collector.acted[0].outcome == "nothing" and collector.acted[0].commands == []


def test_pairplay_robot_try_performs_codes_and_refuses_bad_options(capsys):
    from pairplay.cli.main import main

    assert main(["robot", "--robot", "virtual?time_scale=0", "--try", "35,0"]) == 0
    out = capsys.readouterr().out
    assert "action 35: done" in out and '"text":"Try at row 2 and column 5"' in out and "action 0: nothing" in out
    assert main(["robot", "--robot", "ros://x", "--try", "1"]) == 2
    err = capsys.readouterr().err  # a user's mistake: one line on stderr
    assert "unknown backend" in err and len(err.strip().splitlines()) == 1
    assert main(["robot", "--try", "1", "--calibration", "/nonexistent.json"]) == 2
    assert "cannot read calibration" in capsys.readouterr().err
    with pytest.raises(SystemExit) as refused:  # argparse refuses it, in one line
        main(["robot", "--try", "1,x"])
    assert refused.value.code == 2 and "action codes are integers" in capsys.readouterr().err


def test_robot_none_means_no_bridge():
    import argparse

    from pairplay.cli.robot import add_robot_arguments, bridge_from_args, check_robot_args

    parser = argparse.ArgumentParser()
    add_robot_arguments(parser)
    args = parser.parse_args(["--robot", "none"])
    check_robot_args(args)
    assert bridge_from_args(None, "s", args) is None
    assert parser.parse_args([]).robot == "virtual"


def test_a_bug_on_one_report_costs_that_report_not_the_robot(monkeypatch):
    collector = Collector()
    driver = robot(collector)
    calls = []
    original = driver._match

    def flaky(reply, time_ns):
        calls.append(reply)
        if len(calls) == 1:
            raise RuntimeError("a bug while matching a reply")
        return original(reply, time_ns)

    monkeypatch.setattr(driver, "_match", flaky)
    try:
        driver.perform(suggestion(code_of_parts(2, 0, 0, 0)))
        assert driver.wait_idle(5)  # the speech start was lost to the bug; the end still matches
        driver.perform(suggestion(code_of_parts(2, 0, 0, 0), seq=1))
        assert driver.wait_idle(5)
    finally:
        driver.close()
    assert [a.outcome for a in collector.acted] == ["done", "done"]
