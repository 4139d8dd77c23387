"""A test double of the IrisTK broker, written from its protocol (thesis appendix D).

Rule: it behaves as the broker does on the wire, not as our client happens to
talk. A client's first line must be `CONNECT <ticket> <name>`; an unknown ticket
closes the connection. The broker answers `SUBSCRIBE <filter>` (what the other
clients of the ticket subscribe to, `;`-joined) and then `CONNECTED`; whenever a
client subscribes, every other client of the ticket gets a new SUBSCRIBE line.
`EVENT <name> <n>` is followed by exactly n bytes; the broker relays the event
to the *other* clients of the ticket whose NameFilter matches, re-framed with n
counting a trailing newline. `CLOSE` ends a client. Illegal commands (unknown
lines, bad EVENT headers, anything before CONNECT) are logged and ignored.
Controls for tests: `drop_all()` cuts every connection (the broker "crashes"),
`stop()`/`start()` refuse and accept connections on the same port, and
`inject(name, raw)` writes raw bytes to a client (malformed frames).
"""

from __future__ import annotations

import fnmatch
import logging
import socket
import threading
from dataclasses import dataclass, field

log = logging.getLogger("doubles.iristk_broker")


def segment_match(pattern: list[str], name: list[str]) -> bool:
    """`*` is any one segment (or part of one), `**` any number of segments (one or more)."""
    if not pattern:
        return not name
    head, rest = pattern[0], pattern[1:]
    if head == "**":
        return any(segment_match(rest, name[i:]) for i in range(1, len(name) + 1))
    if not name:
        return False
    return fnmatch.fnmatchcase(name[0], head) and segment_match(rest, name[1:])


def name_filter_matches(spec: str, event_name: str) -> bool:
    """IrisTK NameFilter: `;` alternatives, `!` excludes, `*` / `**` wildcards."""
    terms = [t for t in spec.split(";") if t]
    name = event_name.split(".")
    if any(segment_match(t[1:].split("."), name) for t in terms if t.startswith("!")):
        return False
    including = [t for t in terms if not t.startswith("!")]
    return not including or any(segment_match(t.split("."), name) for t in including)


@dataclass
class BrokerClient:
    sock: socket.socket
    ticket: str = ""
    name: str = ""
    filters: list[str] = field(default_factory=list)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def write(self, data: bytes) -> None:
        with self.lock:
            try:
                self.sock.sendall(data)
            except OSError:
                pass  # the client is gone; its reader thread cleans up

    def wants(self, event_name: str) -> bool:
        return any(name_filter_matches(f, event_name) for f in self.filters)


@dataclass(frozen=True)
class Relayed:
    sender: str
    name: str
    declared: int  # the n the sender wrote
    payload: bytes  # the n bytes read


class IrisTKBroker:
    def __init__(self, tickets: tuple[str, ...] = ("furhat",), port: int = 0) -> None:
        self.tickets = tickets
        self.port = port
        self.clients: list[BrokerClient] = []
        self.events: list[Relayed] = []  # every event a client sent, in arrival order
        self.illegal: list[tuple[str, str]] = []  # (client name or address, what was wrong)
        self.connects: list[tuple[str, str]] = []  # (ticket, name) of every CONNECT accepted
        self.subscribes: list[tuple[str, str]] = []  # (name, filter) of every SUBSCRIBE
        self.closes: list[str] = []  # names of the clients that said CLOSE
        self._lock = threading.Lock()
        self._server: socket.socket | None = None
        self._changed = threading.Condition(self._lock)

    # -- lifecycle --------------------------------------------------------------------------
    def start(self) -> "IrisTKBroker":
        server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        server.bind(("127.0.0.1", self.port))
        server.listen(16)
        self.port = server.getsockname()[1]
        self._server = server
        threading.Thread(target=self._accept, args=(server,), daemon=True, name="broker accept").start()
        return self

    def stop(self) -> None:
        """Stop accepting and drop every client (the broker process died)."""
        server, self._server = self._server, None
        if server is not None:
            try:
                server.shutdown(socket.SHUT_RDWR)  # wakes the blocked accept() and frees the port
            except OSError:
                pass
            server.close()
        self.drop_all()

    def drop_all(self) -> None:
        with self._lock:
            clients, self.clients = self.clients, []
        for client in clients:
            try:
                client.sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            client.sock.close()

    def inject(self, name: str, raw: bytes) -> None:
        for client in self._clients(lambda c: c.name == name):
            client.write(raw)

    def wait_for(self, predicate, timeout: float = 5.0) -> bool:
        """Wait until predicate(self) holds (checked whenever the broker's state changes)."""
        with self._changed:
            return self._changed.wait_for(lambda: predicate(self), timeout)

    # -- the protocol -----------------------------------------------------------------------
    def _accept(self, server: socket.socket) -> None:
        while True:
            try:
                sock, _ = server.accept()
            except OSError:
                return
            threading.Thread(target=self._serve, args=(BrokerClient(sock),), daemon=True).start()

    def _serve(self, client: BrokerClient) -> None:
        stream = client.sock.makefile("rb")
        try:
            while True:
                raw = stream.readline()
                if not raw:
                    break
                line = raw.rstrip(b"\r\n").decode("utf-8", "replace")
                if not self._command(client, line, stream):
                    return
        except (OSError, ValueError):
            pass
        finally:
            self._leave(client)

    def _command(self, client: BrokerClient, line: str, stream) -> bool:
        """Apply one command line (reading an event's bytes); False ends the connection."""
        who = client.name or "unconnected"
        words = line.split(" ")
        if words[0] == "CONNECT" and len(words) == 3 and not client.name:
            return self._connect(client, words[1], words[2])
        if not client.name:
            return self._illegal(who, f"before CONNECT: {line!r}")
        if words[0] == "SUBSCRIBE" and len(words) == 2:
            with self._changed:
                client.filters.append(words[1])
                self.subscribes.append((client.name, words[1]))
                self._changed.notify_all()
            self._announce(client.ticket)
            return True
        if line == "CLOSE":
            with self._changed:
                self.closes.append(client.name)
                self._changed.notify_all()
            return False
        if words[0] == "EVENT" and len(words) == 3 and words[2].isdigit():
            payload = stream.read(int(words[2]))
            if len(payload) < int(words[2]):
                return False  # the connection ended inside the event: nothing is relayed
            self._relay(client, words[1], int(words[2]), payload)
            return True
        return self._illegal(who, f"illegal command {line[:60]!r}")

    def _relay(self, client: BrokerClient, name: str, declared: int, payload: bytes) -> None:
        body = payload.rstrip(b"\n") + b"\n"  # the broker's n counts the trailing newline
        with self._changed:
            self.events.append(Relayed(client.name, name, declared, payload))
            self._changed.notify_all()
        wire = f"EVENT {name} {len(body)}\n".encode() + body
        for other in self._clients(lambda c: c is not client and c.ticket == client.ticket and c.wants(name)):
            other.write(wire)

    def _connect(self, client: BrokerClient, ticket: str, name: str) -> bool:
        if ticket not in self.tickets:
            log.warning("broker: unknown ticket %r from %s", ticket, name)
            return False
        with self._changed:
            client.ticket, client.name = ticket, name
            self.clients.append(client)
            self.connects.append((ticket, name))
            self._changed.notify_all()
        client.write(f"SUBSCRIBE {self._others_filter(client)}\n".encode() + b"CONNECTED\n")
        return True

    def _illegal(self, who: str, what: str) -> bool:
        log.warning("broker: illegal command from %s ignored: %s", who, what)
        with self._changed:
            self.illegal.append((who, what))
            self._changed.notify_all()
        return True

    def _announce(self, ticket: str) -> None:
        for client in self._clients(lambda c: c.ticket == ticket):
            client.write(f"SUBSCRIBE {self._others_filter(client)}\n".encode())

    def _others_filter(self, client: BrokerClient) -> str:
        others = self._clients(lambda c: c is not client and c.ticket == client.ticket)
        return ";".join(f for c in others for f in c.filters)

    def _clients(self, keep) -> list[BrokerClient]:
        with self._lock:
            return [c for c in self.clients if keep(c)]

    def _leave(self, client: BrokerClient) -> None:
        with self._changed:
            if client in self.clients:
                self.clients.remove(client)
            self._changed.notify_all()
        try:
            client.sock.close()
        except OSError:
            pass
        if client.ticket:
            self._announce(client.ticket)
