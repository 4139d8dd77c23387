"""A Zenoh config's keys that pairplay reads have their types, and a bus listening beyond loopback without
TLS is said (services/zenohcheck.py). Before: `{"mode": 5}` was accepted without a word, and a session whose
--zenoh-config listened on tcp/0.0.0.0:0 printed no warning (the lab's --listen did)."""

import json
import logging

import pytest

from pairplay.cli.main import main
from pairplay.services.bus import Bus, BusOptions
from pairplay.services.zenohcheck import beyond_loopback


@pytest.mark.parametrize("config, key", [
    ({"mode": 5}, "mode"),
    ({"mode": "routr"}, "mode"),
    ({"listen": "tcp/127.0.0.1:0"}, "listen"),
    ({"listen": {"endpoints": "tcp/127.0.0.1:0"}}, "listen.endpoints"),
    ({"listen": {"endpoints": [7447]}}, "listen.endpoints"),
    ({"scouting": {"multicast": {"enabled": "yes"}}}, "scouting.multicast.enabled"),
    ({"scouting": {"delay": True}}, "scouting.delay"),
    ({"adminspace": []}, "adminspace"),
])
def test_a_wrong_type_of_a_key_we_read_is_refused_in_one_line_naming_it(tmp_path, capsys, config, key):
    path = tmp_path / "z.json5"
    path.write_text(json.dumps(config))
    assert main(["session", "--participant", "sim:ashley", "--rounds", "1", "--session", "zt", "--out",
                 str(tmp_path / "rec"), "--zenoh-config", str(path)]) == 2
    out, err = capsys.readouterr()
    assert out == "" and len(err.strip().splitlines()) == 1, err
    assert f"{key} must be" in err and str(path) in err, err
    assert not (tmp_path / "rec" / "zt.mcap").exists()


def test_a_config_of_the_right_types_opens(tmp_path):
    path = tmp_path / "z.json5"
    path.write_text(json.dumps({"mode": "peer", "listen": {"endpoints": {"peer": ["tcp/127.0.0.1:0"]}},
                                "scouting": {"delay": 50, "multicast": {"enabled": False}},
                                "timestamping": {"enabled": {"router": True, "peer": False}}}))
    with Bus(BusOptions(zenoh_config=str(path))) as bus:
        assert bus.locators()


@pytest.mark.parametrize("endpoint, beyond", [
    ("tcp/127.0.0.1:0", False), ("tcp/[::1]:7447", False), ("tcp/localhost:7447", False),
    ("unixsock-stream//tmp/z.sock", False), ("tcp/0.0.0.0:0", True), ("tcp/[::]:7447", True),
    ("udp/192.168.1.4:7447", True), ("tcp/server.lab:7447", True), ("tls/0.0.0.0:7447", True),
])
def test_which_listeners_reach_beyond_loopback(endpoint, beyond):
    assert beyond_loopback(endpoint) == beyond


def test_a_bus_listening_beyond_loopback_without_tls_is_said_once(tmp_path, caplog):
    path = tmp_path / "z.json5"
    path.write_text(json.dumps({"listen": {"endpoints": ["tcp/0.0.0.0:0"]}}))
    with caplog.at_level(logging.WARNING, logger="pairplay.bus"):
        with Bus(BusOptions(mode="peer", zenoh_config=str(path))):
            pass
        with Bus(BusOptions(mode="peer", listen=["tcp/127.0.0.1:0"])):
            pass
    said = [r.getMessage() for r in caplog.records if "beyond loopback" in r.getMessage()]
    assert len(said) == 1 and "tcp/0.0.0.0:0" in said[0] and "TLS" in said[0], said


def test_a_session_whose_config_listens_beyond_loopback_warns_on_stderr_in_one_line(tmp_path, pairplay_cli):
    path = tmp_path / "z.json5"
    path.write_text(json.dumps({"listen": {"endpoints": ["tcp/0.0.0.0:0"]}}))
    r = pairplay_cli("session", "--participant", "sim:ashley", "--rounds", "1", "--session", "wide", "--out", "rec",
                     "--zenoh-config", path, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    lines = [line for line in r.stderr.splitlines() if "beyond loopback" in line]
    assert len(lines) == 1 and "tcp/0.0.0.0:0" in lines[0] and "WARNING" in lines[0], r.stderr


def _free_udp_port() -> int:
    import socket
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize("scouting, said", [
    ({"multicast": {"enabled": True}}, "multicast scouting on UDP 224.0.0.224:{port}"),
    ({"gossip": {"enabled": True}}, "gossip scouting"),
])
def test_a_bus_whose_config_scouts_beyond_loopback_is_said_once(tmp_path, caplog, scouting, said):
    # trial28 F17: multicast scouting opened UDP on 0.0.0.0 and 224.0.0.224:7446 without a word, while a
    # listener on 0.0.0.0 was warned of. A group port of its own: no other test's bus scouts with it
    port = _free_udp_port()
    if "multicast" in scouting:
        scouting["multicast"]["address"] = f"224.0.0.224:{port}"
    path = tmp_path / "z.json5"
    path.write_text(json.dumps({"scouting": scouting}))
    with caplog.at_level(logging.WARNING, logger="pairplay.bus"):
        with Bus(BusOptions(mode="peer", listen=["tcp/127.0.0.1:0"], zenoh_config=str(path))):
            pass
        with Bus(BusOptions(mode="peer", listen=["tcp/127.0.0.1:0"])):  # pairplay's defaults: both off
            pass
    lines = [r.getMessage() for r in caplog.records if "beyond loopback" in r.getMessage()]
    assert len(lines) == 1 and "scouts beyond loopback" in lines[0] and said.format(port=port) in lines[0], lines


def test_a_key_given_twice_in_the_zenoh_config_is_refused_in_one_line_naming_it(tmp_path, capsys):
    # trial28 F17: json5 kept the last, so `enabled: false, enabled: true` turned multicast scouting on silently
    path = tmp_path / "z.json5"
    path.write_text("{scouting: {multicast: {enabled: false, enabled: true}}}")
    assert main(["session", "--participant", "sim:ashley", "--rounds", "1", "--session", "zt", "--out",
                 str(tmp_path / "rec"), "--zenoh-config", str(path)]) == 2
    out, err = capsys.readouterr()
    assert out == "" and len(err.strip().splitlines()) == 1, err
    assert "scouting.multicast: the key `enabled` is given twice" in err and str(path) in err, err
    assert not (tmp_path / "rec" / "zt.mcap").exists()
