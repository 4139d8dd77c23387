"""A person's session: settings a person cannot satisfy are refused everywhere (config,
game, both verbs), and the defaults are the human phase of thesis 7.2."""

from __future__ import annotations

import argparse
import subprocess
import sys

import pytest

from pairplay.cli.session import add_config_arguments, config_from_args
from pairplay.schemas.config import LearnerConfig
from pairplay.schemas.session import SessionConfig, learner_overrides
from pairplay.services.game import GameLogic


def human(**fields) -> SessionConfig:
    fields = {"observed_source": "first-pick", "ignore_rule": "time"} | fields
    return SessionConfig(session="h", participant="human:p1", seed=0, rounds=5, **fields)


@pytest.mark.parametrize("fields, words", [
    ({"ignore_rule": "perceived"}, "ignore rule 'perceived' needs a simulated participant"),
    ({"observed_source": "intended"}, "observed source 'intended' needs a simulated participant"),
    ({"ignore_clock": "sundial"}, "ignore_clock"),
    ({"ignore_window_ms": -1.0}, "ignore_window_ms must be 0..60000, got -1"),
])
def test_a_person_cannot_be_asked_what_only_a_simulation_reports(fields, words):
    # a field alone is refused where the config is made (its __post_init__): no config, no game to start
    for check in (lambda: human(**fields).validate(), lambda: GameLogic(human(**fields))):  # the game refuses it too
        with pytest.raises(ValueError, match=words.replace("(", r"\(").replace(")", r"\)")):
            check()


def test_gaze_is_for_people_and_first_pick_or_gaze_are_fine():
    human(observed_source="gaze").validate()
    human().validate()
    with pytest.raises(ValueError, match="gaze"):
        SessionConfig(session="s", participant="sim:blind", persona="blind", seed=0, rounds=1,
                      observed_source="gaze").validate()


def parse(*argv: str) -> SessionConfig:
    p = argparse.ArgumentParser()
    add_config_arguments(p)
    return config_from_args(p.parse_args(list(argv)))


def test_a_person_gets_the_human_phase_schedules_and_five_rounds():
    c = parse("--participant", "human:p1", "--session", "x")
    assert c.rounds == 5 and c.learner == learner_overrides(LearnerConfig.human_phase1(5))
    assert (c.observed_source, c.ignore_rule, c.ignore_clock, c.ignore_window_ms) == ("first-pick", "time", "page",
                                                                                      1500.0)
    c = parse("--participant", "human:p1", "--session", "x", "--rounds", "4", "--ignore-window-ms", "1200")
    assert c.learner == learner_overrides(LearnerConfig.human_phase1(4)) and c.ignore_window_ms == 1200.0
    sim = parse("--participant", "sim:blind", "--session", "x")
    assert sim.rounds == 20 and sim.learner == {} and sim.ignore_clock == "server"


@pytest.fixture
def pairplay(pairplay_cli):
    """`python -m pairplay ARGS`, each its own process (conftest's pairplay_cli)."""
    return lambda *args: pairplay_cli(*args, timeout=60)


@pytest.mark.parametrize("args, words", [
    (["--ignore-rule", "perceived"], "ignore rule 'perceived'"),
    (["--observed-source", "intended"], "observed source 'intended'"),
    (["--listen", "nowhere"], "--listen 'nowhere'"),
    (["--certfile", "cert.pem"], "--certfile and --keyfile go together"),
])
def test_pairplay_lab_refuses_with_one_line(tmp_path, args, words, pairplay):
    r = pairplay("lab", "--participant", "human:p1", "--out", str(tmp_path), *args)
    assert r.returncode == 2 and r.stdout == "" and words in r.stderr
    assert r.stderr.count("\n") == 1 and "Traceback" not in r.stderr


def test_the_lab_is_for_people_and_session_refuses_the_same(tmp_path, pairplay):
    r = pairplay("lab", "--participant", "sim:blind", "--out", str(tmp_path))
    assert r.returncode == 2 and "the lab is for a person" in r.stderr
    r = pairplay("session", "--participant", "human:p1", "--ignore-rule", "perceived", "--out", str(tmp_path))
    assert r.returncode == 2 and "ignore rule 'perceived'" in r.stderr and r.stderr.count("\n") == 1


@pytest.mark.parametrize("tls", [False, True], ids=["http", "https"])
def test_pairplay_lab_says_where_the_board_is_and_stops_on_sigterm(tmp_path, tls):
    import shutil
    import signal
    import ssl
    import urllib.request

    extra = []
    context = None
    if tls:
        if shutil.which("openssl") is None:
            pytest.skip("no openssl to make a test certificate")
        cert, key = tmp_path / "lab.pem", tmp_path / "lab-key.pem"
        subprocess.run(["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "1", "-subj",
                        "/CN=127.0.0.1", "-keyout", str(key), "-out", str(cert)], check=True, capture_output=True)
        extra = ["--certfile", str(cert), "--keyfile", str(key)]
        context = ssl.create_default_context(cafile=str(cert))
        context.check_hostname = False  # the certificate names 127.0.0.1 as CN only
    proc = subprocess.Popen([sys.executable, "-m", "pairplay", "lab", "--participant", "human:p9", "--session",
                             "sig", "--out", str(tmp_path), *extra], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        lines = [proc.stdout.readline() for _ in range(3)]
        board = lines[1].split()[1]
        scheme = "https" if tls else "http"
        assert lines[1].startswith(f"board:  {scheme}://127.0.0.1:") and "/s/sig/board?t=" in board
        assert lines[2].startswith("mirror: ")
        handlers = [urllib.request.ProxyHandler({})] + ([urllib.request.HTTPSHandler(context=context)] if tls else [])
        direct = urllib.request.build_opener(*handlers)  # loopback: never a proxy
        assert b"Wrong suggestion" in direct.open(board, timeout=10).read()
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
    # no study folder, no consent to check: said beside the URLs (a researcher expected `protocol serve`'s check;
    # before, not a word: trial33 H)
    assert "\nconsent: not checked here (one session outside any study folder; a study's games, each person's " \
           "consent checked first, run from `pairplay protocol serve FOLDER`)\n" in out, out
    # the game may not have started the session yet (it waits for its services): either way the signal is named
    assert proc.returncode == 143 and "interrupted (SIGTERM" in err and "Traceback" not in err, out + err
    assert "interrupted" not in out, out  # stdout holds results only
    assert (tmp_path / "sig.mcap").stat().st_size > 0
