"""The IrisTK client against IrisTK's own broker (Broker.java, compiled from its source), when one is at hand.

Runs only with PAIRPLAY_IRISTK_SRC set to a checkout of gabriel-skantze/IrisTK and a
`javac` on the PATH: core/src/iristk/system/Broker.java, util/NameFilter.java and
util/ParsedInputStream.java are compiled as they are, beside three small stand-ins
for what they import (robot_doubles/iristk_java_stubs: a logger and Event.toJSON);
skipped otherwise, as CI has neither. The robot side is the Furhat double.
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import time
from pathlib import Path

import msgspec
import pytest
from robot_doubles.harness import FAMILIES, FAST, PATIENCE_S, Collector, suggestion
from robot_doubles.iristk_furhat import IrisTKFurhat

from pairplay.core.actions import code_of_parts
from pairplay.services.robot import open_robot
from pairplay.services.robot.iristk_protocol import event_frame, make_event

SOURCE = os.environ.get("PAIRPLAY_IRISTK_SRC", "")
STUBS = Path(__file__).parent / "robot_doubles" / "iristk_java_stubs"
pytestmark = pytest.mark.skipif(not SOURCE or not shutil.which("javac"),
                                reason="no IrisTK source (PAIRPLAY_IRISTK_SRC) or no javac")


@pytest.fixture(scope="module")
def classes(tmp_path_factory) -> str:
    out = tmp_path_factory.mktemp("iristk-classes")
    core = Path(SOURCE) / "core" / "src" / "iristk"
    sources = [core / "system" / "Broker.java", core / "util" / "NameFilter.java",
               core / "util" / "ParsedInputStream.java", *STUBS.rglob("*.java")]
    subprocess.run(["javac", "-d", str(out), *map(str, sources)], check=True, capture_output=True)
    return str(out)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _start(classes: str, port: int, log) -> subprocess.Popen:
    broker = subprocess.Popen(["java", "-cp", classes, "iristk.system.Broker", str(port)],
                              stdout=subprocess.DEVNULL, stderr=log)
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
            return broker
        except OSError:
            time.sleep(0.05)
    broker.kill()
    raise RuntimeError("IrisTK broker did not start")


def test_against_irisTKs_own_broker(tmp_path, classes):
    port, log_path = _free_port(), tmp_path / "broker.log"
    with open(log_path, "wb") as log:
        broker = _start(classes, port, log)
        furhat = IrisTKFurhat(port, speech_s=0.3).start()
        collector = Collector()
        config = msgspec.structs.replace(FAST, give_up_s=30.0)  # a JVM restart on a loaded machine takes seconds
        driver = open_robot(f"iristk://127.0.0.1:{port}", collector.on_acted, config=config,
                            on_rejected=collector.on_rejected)
        other = socket.create_connection(("127.0.0.1", port))
        try:
            for seq, code in enumerate(FAMILIES.values()):
                driver.perform(suggestion(code, seq=seq))
                assert driver.wait_idle(PATIENCE_S)
            assert [a.outcome for a in collector.acted] == ["done", "done", "done", "done", "sent", "sent"]
            other.sendall(b"CONNECT furhat other\n")
            furhat.speech_s = 3.0
            driver.perform(suggestion(code_of_parts(2, 0, 0, 0), seq=10))
            assert furhat.wait_for(lambda f: f.replies and f.replies[-1]["event_name"] == "monitor.speech.start")
            other.sendall(event_frame(make_event("action.speech.stop", "other.1", "other", time.time_ns())))
            assert driver.wait_idle(PATIENCE_S)
            assert collector.acted[-1].outcome == "stopped"
            other.sendall("EVENT monitor.speech.end \u0663\n".encode() + b"{}x")  # Java's parseInt reads 3
            assert collector.wait_for(lambda c: len(c.rejected) == 1)
            furhat.speech_s = 0.05
            broker.kill()
            broker.wait()
            broker = _start(classes, port, log)  # the robot double rejoins; nothing goes before it has
            driver.perform(suggestion(code_of_parts(2, 0, 0, 0), seq=20))
            assert driver.wait_idle(40)
            assert collector.acted[-1].outcome == "done" and driver.reconnects == 1
        finally:
            other.close()
            driver.close()
            furhat.close()
            time.sleep(0.3)
            broker.kill()
            broker.wait()
    text = log_path.read_text(errors="replace")
    assert "Exception" not in text and "pipe" not in text.lower(), text  # no broken pipe, no stack trace
    assert "Disconnection from furhat from pairplay" in text  # we left with CLOSE
