"""What a Zenoh config lets in: the types of the keys pairplay reads, and listeners beyond loopback.

Rule: a --zenoh-config file is laid over pairplay's defaults key by key (services/bus.py); every
key of it that pairplay itself reads or sets (`TYPES`) must have the type Zenoh gives it, or the
file is refused, naming the key (`{"mode": 5}` was taken without a word: our mode replaced it, and
`{"listen": "tcp/..."}` met a TypeError). Zenoh checks the rest when it opens the session. A bus
whose listeners reach beyond loopback (any address but 127.0.0.0/8, ::1 and localhost, over any
link but a unix socket) without TLS (`tls/`, `quic/`) lets anyone on the network read and write
the session: every verb that opens such a bus says so in one warning line (stderr, the
log's), as `pairplay lab --listen` does for its web server. Scouting that reaches beyond
loopback (`scouting_beyond`: multicast scouting, which opens UDP on every interface whatever
the listeners, or gossip) is said alike, in a line of its own: a config that turned multicast
on opened 0.0.0.0 and 224.0.0.224:7446 without a word (trial28 F17).
"""

from __future__ import annotations

import ipaddress
from typing import Any

MODES = ("peer", "client", "router")
_ENDPOINTS = "a list of endpoint strings (or an object of them per mode)"
# key path -> (the types allowed, in words)
TYPES: dict[tuple[str, ...], tuple[tuple[type, ...], str]] = {
    ("mode",): ((str,), f"one of {', '.join(MODES)}"),
    ("listen",): ((dict,), "an object"),
    ("listen", "endpoints"): ((list, dict), _ENDPOINTS),
    ("connect",): ((dict,), "an object"),
    ("connect", "endpoints"): ((list, dict), _ENDPOINTS),
    ("connect", "retry"): ((dict,), "an object"),
    ("scouting",): ((dict,), "an object"),
    ("scouting", "delay"): ((int,), "a whole number of milliseconds"),
    ("scouting", "multicast"): ((dict,), "an object"),
    ("scouting", "multicast", "enabled"): ((bool,), "true or false"),
    ("scouting", "gossip"): ((dict,), "an object"),
    ("scouting", "gossip", "enabled"): ((bool,), "true or false"),
    ("adminspace",): ((dict,), "an object"),
    ("adminspace", "enabled"): ((bool,), "true or false"),
    ("timestamping",): ((dict,), "an object"),
    ("timestamping", "enabled"): ((bool, dict), "true or false (or an object of them per mode)"),
}
LOCAL_LINKS = ("unixsock-stream", "unixpipe")  # never leave the host
SECURE_LINKS = ("tls", "quic")


def _is(value: Any, types: tuple[type, ...]) -> bool:
    if isinstance(value, bool) and bool not in types:  # JSON's true is not a number
        return False
    return isinstance(value, types)


def type_errors(data: dict) -> list[str]:
    """What is wrong with the types of the keys of `data` (a config file) that pairplay reads, in
    words ("listen.endpoints must be ..., not a number (5)"); [] if nothing."""
    wrong = []
    for path, (types, words) in TYPES.items():
        node: Any = data
        for k in path:
            if not isinstance(node, dict) or k not in node:
                break
            node = node[k]
        else:
            name = ".".join(path)
            if not _is(node, types) or (path == ("mode",) and node not in MODES):
                wrong.append(f"{name} must be {words}, not {node!r}")
            elif path[-1] == "endpoints":
                lists = node.values() if isinstance(node, dict) else [node]
                if not all(isinstance(v, list) and all(isinstance(e, str) for e in v) for v in lists):
                    wrong.append(f"{name} must be {words}, not {node!r}")
    return wrong


def _host(endpoint: str) -> tuple[str, str]:
    """(link, host) of a Zenoh endpoint `link/host:port[?meta][#config]`."""
    link, _, rest = endpoint.partition("/")
    address = rest.split("#", 1)[0].split("?", 1)[0]
    if address.startswith("["):  # [::1]:7447
        return link, address[1:address.find("]")] if "]" in address else address
    return link, address.rsplit(":", 1)[0] if ":" in address else address


def beyond_loopback(endpoint: str) -> bool:
    """Whether a listener on `endpoint` can be reached from other hosts."""
    link, host = _host(endpoint)
    if link in LOCAL_LINKS:
        return False
    if host == "localhost":
        return False
    try:
        return not ipaddress.ip_address(host.split("%", 1)[0]).is_loopback
    except ValueError:  # a host name or an interface: reachable, as far as we can tell
        return True


def exposed(cfg: dict) -> list[str]:
    """The listen endpoints of a whole config (BusOptions.to_dict) reachable from other hosts without
    TLS: what the warning names."""
    endpoints = (cfg.get("listen") or {}).get("endpoints") or []
    if isinstance(endpoints, dict):  # per mode
        endpoints = endpoints.get(cfg.get("mode", ""), [])
    return [e for e in endpoints if isinstance(e, str) and _host(e)[0] not in SECURE_LINKS and beyond_loopback(e)]


MULTICAST = "224.0.0.224:7446"  # Zenoh's default scouting group


def scouting_beyond(cfg: dict) -> list[str]:
    """The scouting of a whole config (BusOptions.to_dict) that reaches beyond loopback, in words: multicast
    scouting (Zenoh opens UDP on every interface, 0.0.0.0, and joins its group, 224.0.0.224:7446 by default,
    whatever the listen endpoints) and gossip (peers pass on the addresses of others, and it connects to them);
    [] with both off, as pairplay's defaults have them (bus.safe_defaults). What the warning names."""
    scouting = cfg.get("scouting") or {}
    multicast, gossip = scouting.get("multicast") or {}, scouting.get("gossip") or {}
    found = []
    if multicast.get("enabled") is True:
        found.append(f"multicast scouting on UDP {multicast.get('address', MULTICAST)}")
    if gossip.get("enabled") is True:
        found.append("gossip scouting")
    return found
