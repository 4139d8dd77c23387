"""TLS and access control with the shipped example configs (docs/examples), on loopback:
a test CA made by docs/examples/make_test_ca.sh; the study server as `pairplay session`
(router, mTLS, access control); the board and robot hosts as clients with their own
certificates. A client without a certificate cannot connect (one line, non-zero exit);
a client publishing outside its rights is refused by the router, and the refusal shows in
the router's access-control log; what it may publish is recorded."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import json5
import pytest

from pairplay.replay.reader import read_log
from pairplay.schemas import events as ev
from pairplay.schemas.envelope import stamped
from pairplay.schemas.events import encode_event
from pairplay.schemas.keys import event_key
from pairplay.schemas.robot import RobotActed
from pairplay.services.bus import Bus, BusOpenError, BusOptions


EXAMPLES = Path(__file__).resolve().parents[1] / "docs" / "examples"
ACL_LOG = "zenoh::net::routing::interceptor::access_control=trace"


def render(name: str, certs: Path, out: Path, host: str | None = "server") -> Path:
    """An example config with its certificate paths made absolute; a client's certificate is
    `host`'s (None: the client has none)."""
    cfg = json5.loads((EXAMPLES / name).read_text())
    tls = cfg["transport"]["link"]["tls"]
    for k, v in list(tls.items()):
        if isinstance(v, str) and v.startswith("certs/"):
            tls[k] = str(certs / v.removeprefix("certs/"))
    if host is None:
        for k in ("connect_certificate", "connect_private_key", "enable_mtls"):
            tls.pop(k, None)
    elif "connect_certificate" in tls:
        tls["connect_certificate"] = str(certs / f"{host}.pem")
        tls["connect_private_key"] = str(certs / f"{host}.key")
    path = out / f"{name}.{host or 'nocert'}.json5"
    assert "server" not in name or tls.get("enable_mtls") is True
    path.write_text(json5.dumps(cfg))
    return path


@pytest.fixture(scope="module")
def certs(tmp_path_factory):
    out = tmp_path_factory.mktemp("certs")
    subprocess.run(["sh", str(EXAMPLES / "make_test_ca.sh"), str(out)], check=True, capture_output=True)
    return out


def test_tls_and_access_control_refuse_visibly_and_let_the_rights_through(tmp_path, certs):
    server = render("zenoh-tls-server.json5", certs, tmp_path)
    # rounds enough to outlast the test on a loaded machine: the session must still be running (and
    # recording) when the robot host puts; a 300-round session could end first under xdist (seen twice)
    p = subprocess.Popen([sys.executable, "-m", "pairplay", "session", "--participant", "sim:ashley", "--rounds",
                          "5000", "--session", "sec1", "--out", str(tmp_path), "--listen", "tls/127.0.0.1:0",
                          "--zenoh-config", str(server)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         env=dict(os.environ, PYTHONUNBUFFERED="1", RUST_LOG=ACL_LOG))
    try:
        head = []  # Zenoh's log (RUST_LOG) goes to stdout too
        while "bus listening on " not in (head[-1] if head else ""):
            head.append(p.stdout.readline())
        endpoint = head[-1].split("bus listening on ", 1)[1].split()[0]
        assert endpoint.startswith("tls/127.0.0.1:")
        connect = [endpoint.replace("127.0.0.1", "localhost")]  # the name the server's certificate carries

        # no certificate: the TLS handshake is refused; `pairplay run` says so in one line
        nocert = render("zenoh-tls-client.json5", certs, tmp_path, host=None)
        with pytest.raises(BusOpenError):
            Bus(BusOptions(mode="client", connect=connect, zenoh_config=str(nocert)))
        r = subprocess.run([sys.executable, "-m", "pairplay", "run", "learner", "--session", "sec1", "--connect",
                            connect[0], "--zenoh-config", str(nocert)], capture_output=True, text=True, timeout=60)
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "cannot open the bus" in r.stderr

        # the robot host: RobotActed is its right, a game event is not
        robot_cfg = render("zenoh-tls-client.json5", certs, tmp_path, host="robot")
        with Bus(BusOptions(mode="client", connect=connect, zenoh_config=str(robot_cfg))) as robot:
            with Bus(BusOptions(mode="client", connect=connect,
                                zenoh_config=str(render("zenoh-tls-client.json5", certs, tmp_path, "board")))) as board:
                seen = []
                board.subscribe("pairplay/sec1/**", lambda k, _p: seen.append(k))
                acted = stamped(RobotActed(round=0, turn=0, attempt=0, action=1, backend="virtual", outcome="done"),
                                session="sec1", source="robot", seq=1, time_ns=time.time_ns())
                forged = stamped(ev.SessionEnded(reason="forged"), session="sec1", source="game", seq=2,
                                 time_ns=time.time_ns())
                # a subscription takes a moment to reach the router: put until the board sees it (pub/sub keeps
                # no history), then the forged end, which the router must drop
                deadline = time.monotonic() + 30
                while "pairplay/sec1/robot/RobotActed" not in seen and time.monotonic() < deadline:
                    robot.put(event_key("sec1", "robot", "RobotActed"), encode_event(acted))
                    time.sleep(0.5)
                assert "pairplay/sec1/robot/RobotActed" in seen
                robot.put(event_key("sec1", "game", "SessionEnded"), encode_event(forged))
                time.sleep(0.5)
        p.send_signal(signal.SIGTERM)
        out, err = p.communicate(timeout=30)
    finally:
        p.kill()
    # the router refused the forged end, visibly in its access-control log (Zenoh logs to stdout)
    assert "is unauthorized to Put (ingress) on pairplay/sec1/game/SessionEnded" in "".join(head) + out + err
    assert "pairplay/sec1/game/SessionEnded" not in seen[:seen.index("pairplay/sec1/robot/RobotActed") + 2]
    events = [r.event for r in read_log(tmp_path / "sec1.mcap").events]
    assert not [e for e in events if isinstance(e, ev.SessionEnded) and e.reason == "forged"]
    assert [e for e in events if isinstance(e, RobotActed) and e.source == "robot"]


def test_a_host_answers_only_for_the_sources_it_may_publish(tmp_path, certs):
    """trial34 O: the robot host (its rights: put robot/**) answered the recorder's catch-up question
    `_query/learner/sent` with a forged learner event, which the recorder wrote. Under the example's access control
    a host declares queryables, replies and tokens only for the sources it may publish: the robot's queryable on the
    learner's question gets no query and its reply never reaches the asker, while its own source's answer does."""
    from pairplay.schemas.keys import alive_key, query_key
    router = Bus(BusOptions(mode="router", listen=["tls/127.0.0.1:0"],
                            zenoh_config=str(render("zenoh-tls-server.json5", certs, tmp_path))))
    try:
        endpoint = [e for e in router.locators() if e.startswith("tls/")][0]
        connect = [endpoint.replace("127.0.0.1", "localhost")]  # the name the server's certificate carries

        def client(host: str) -> Bus:
            return Bus(BusOptions(mode="client", connect=connect,
                                  zenoh_config=str(render("zenoh-tls-client.json5", certs, tmp_path, host))))
        asked: list[str] = []
        with client("server") as server, client("robot") as robot, client("board") as asker:
            def answering(who: str, what: bytes):
                def on_query(query) -> None:
                    asked.append(who)
                    Bus.answer(query, [what])
                return on_query
            server.queryable(query_key("sec2", "learner", "sent"), answering("server", b"learner's own"))
            robot.queryable(query_key("sec2", "learner", "sent"), answering("forger", b"forged by the robot host"))
            robot.queryable(query_key("sec2", "robot", "sent"), answering("robot", b"robot's own"))
            robot.alive(alive_key("sec2", "learner"))
            robot.alive(alive_key("sec2", "robot"))
            # a declaration takes a moment to reach the router: ask until both rightful answers came (each ask
            # gathers every reply), then once more, so the forger had as long as the rightful ones
            got: list[bytes] = []
            deadline = time.monotonic() + 30
            while not {b"learner's own", b"robot's own"} <= set(got) and time.monotonic() < deadline:
                got += asker.query(query_key("sec2", "*", "sent") + "?after=learner:0", timeout_s=1.0)
            before = len(asked)
            got += asker.query(query_key("sec2", "learner", "sent") + "?after=learner:0", timeout_s=1.0)
            # (a question to every source reaches the robot's session, which hands it to each of its queryables:
            # there its reply on the learner's key is what the router drops)
            asked_learner = asked[before:]
            tokens = asker.alive_now(alive_key("sec2", "*"), timeout_s=1.0)
    finally:
        router.close()
    assert b"learner's own" in got and b"robot's own" in got
    assert b"forged by the robot host" not in got
    assert asked_learner == ["server"]  # the learner's own question reaches the server's session only
    assert tokens == {alive_key("sec2", "robot")}  # nor let announce itself as the learner
