"""The bus layer: one config for every mode, the Zenoh file passed through,
router + clients for several hosts, and a clean exit on SIGTERM/SIGINT."""

import json
import signal
import subprocess
import sys

from pairplay.replay.reader import read_log
from pairplay.services.bus import Bus, BusOptions

from busutil import collect, listener, wait_until


def test_the_embedded_default_is_a_loopback_peer_without_scouting():
    config = BusOptions().to_zenoh()
    assert json.loads(config.get_json("mode")) == "peer"
    assert json.loads(config.get_json("listen/endpoints")) == ["tcp/127.0.0.1:0"]
    assert json.loads(config.get_json("scouting/multicast/enabled")) is False
    assert json.loads(config.get_json("scouting/gossip/enabled")) is False
    with Bus() as bus:
        (endpoint,) = bus.locators()
        assert endpoint.startswith("tcp/127.0.0.1:") and not endpoint.endswith(":0")  # the real port


def test_a_zenoh_config_file_is_passed_through_with_our_options_over_it(tmp_path):
    path = tmp_path / "zenoh.json5"
    path.write_text(json.dumps({
        "mode": "peer", "scouting": {"multicast": {"enabled": False}},
        "access_control": {"enabled": True, "default_permission": "allow"},
        "transport": {"link": {"tls": {"enable_mtls": False}}}}))
    config = BusOptions(mode="client", connect=["tcp/127.0.0.1:7447"], zenoh_config=str(path)).to_zenoh()
    assert json.loads(config.get_json("access_control/enabled")) is True  # untouched
    assert json.loads(config.get_json("mode")) == "client"  # ours over it
    assert json.loads(config.get_json("connect/endpoints")) == ["tcp/127.0.0.1:7447"]


def test_services_on_several_hosts_meet_through_a_router():
    with Bus(BusOptions(mode="router")) as router:
        (endpoint,) = router.locators()
        with Bus(BusOptions(mode="client", connect=[endpoint])) as a, \
                Bus(BusOptions(mode="client", connect=[endpoint])) as b:
            got = collect(b, "pairplay/x/**")
            assert wait_until(lambda: a.matching("pairplay/x/game/Ping"))
            for i in range(100):
                a.put("pairplay/x/game/Ping", str(i).encode())
            assert wait_until(lambda: got.qsize() == 100)
            assert [got.get()[1] for _ in range(100)] == [str(i).encode() for i in range(100)]


def test_services_exit_cleanly_on_sigterm_and_sigint(tmp_path):
    with listener() as bus:
        endpoint = bus.locators()[0]
        procs = {
            "recorder": subprocess.Popen([sys.executable, "-m", "pairplay", "run", "recorder", "--session", "quit",
                                          "--out", str(tmp_path), "--connect", endpoint], stdout=subprocess.PIPE),
            "learner": subprocess.Popen([sys.executable, "-m", "pairplay", "run", "learner", "--session", "quit",
                                         "--connect", endpoint], stdout=subprocess.PIPE),
        }
        for name, p in procs.items():
            assert wait_until(lambda: f"pairplay/quit/_alive/{name}" in bus.alive_now("pairplay/quit/_alive/*"), 30)
        procs["recorder"].send_signal(signal.SIGTERM)
        procs["learner"].send_signal(signal.SIGINT)
        codes = {name: p.wait(20) for name, p in procs.items()}
    assert codes == {"recorder": 143, "learner": 130}  # 128 + the signal (cli/main.py), its file finished
    log = read_log(tmp_path / "quit.mcap")
    assert not log.truncated  # the recorder finished its file on the way out
    assert log.metadata["pairplay.recorder"]["session"] == "quit"
