"""Who can reach a verb's web server (the board, the console), and the one warning when others can in clear text.

Rule: every verb that serves HTTP/WebSocket (`pairplay lab`, `pairplay protocol serve`: both run
services/lab/server.py's WebServer) says the same warning when it listens beyond loopback without TLS
(`plain_beyond_loopback`): the board's and the console's tokens, and the console's token can export and delete
participants' data, travel in clear text (README: "Serving the board beyond loopback"). And the URLs printed name
an address another device can open: a wildcard host (0.0.0.0, ::) is printed as this machine's address on its
network (`reachable_host`), not as 127.0.0.1, which on the touch screen names the touch screen.
"""

from __future__ import annotations

import ipaddress
import socket

from pairplay.services.zenohcheck import beyond_loopback

WILDCARDS = ("", "0.0.0.0", "::")
# documentation addresses (RFC 5737, RFC 3849): a UDP socket "connected" to one sends nothing, and its own address
# is the one the system's routes use to leave the machine, i.e. the address the LAN sees
_OUTSIDE = {socket.AF_INET: "192.0.2.1", socket.AF_INET6: "2001:db8::1"}


def plain_beyond_loopback(host: str, tls: bool) -> str | None:
    """The warning (no verb's name) for a web server on `host` without TLS, or None if none is owed."""
    if tls or not beyond_loopback(f"tcp/{host}:0"):
        return None
    return "warning: serving beyond loopback without TLS (README: serving the board beyond loopback)"


def reachable_host(host: str) -> str:
    """`host` as a URL's host another device can use: a wildcard becomes this machine's network address
    (127.0.0.1 when it has none: nothing else could reach it anyway); an IPv6 address is bracketed."""
    if host in WILDCARDS:
        host = _own_address(socket.AF_INET6 if host == "::" else socket.AF_INET) or _own_address(socket.AF_INET) \
            or "127.0.0.1"
    return f"[{host}]" if ":" in host else host


def _own_address(family: int) -> str | None:
    try:
        with socket.socket(family, socket.SOCK_DGRAM) as s:
            s.connect((_OUTSIDE[family], 9))  # a UDP connect sends no packet: it only picks the route
            address = s.getsockname()[0]
    except OSError:  # no route out (no network): no address to give
        return None
    return None if ipaddress.ip_address(address.split("%", 1)[0]).is_loopback else address
