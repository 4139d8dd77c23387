"""A test double of the IrisTK broker, written from IrisTK's core/src/iristk/system/Broker.java.

Rule: on the wire it does what Broker.java does (gabriel-skantze/IrisTK, read, not
copied), line numbers cited:
  lines     a line ends at "\\n" or "\\r" (ParsedInputStream.readTo(10, 13)); at
            EOF the Java reader returns "" for ever, so a client that leaves
            without CLOSE is never removed (it stays registered, a zombie: 220-223);
            a read error (connection reset) removes it (286-288)
  CONNECT   `CONNECT <ticket> <name>`, any ticket (a new system is made, 95-102),
            two non-empty words after trim or it is illegal (224-227); then the
            SUBSCRIBE updates (232) and `CONNECTED` (233)
  SUBSCRIBE pattern = rest after "SUBSCRIBE ", trimmed, "" meaning "**" (268-271);
            a pattern NameFilter.compile refuses is an illegal command and the
            old subscription stays (272-277)
  updates   every client of the ticket whose union of the *other* clients'
            filters changed gets `SUBSCRIBE <union>` (121-139; NONE is "")
  EVENT     `EVENT <label> <n>`: two words after trim (244-246), n by
            Integer.parseInt (so "+3" and "٣" pass, 248-253), then n bytes; relayed
            to every other client of the ticket whose filter accepts the label
            (85-93) as `EVENT <label> <n+1>\\n` + bytes + "\\n" (188-191, the
            payload re-encoded through a String on a UTF-8 JVM); a negative n
            or an EVENT before CONNECT ends the client's thread (289-291)
  CLOSE     any line starting with "CLOSE" (264): the client is removed, the
            others get SUBSCRIBE updates and a monitor.system.disconnected event
            (104-119), then the socket is closed (197-208)
  other     any other line is ignored without a word (no else branch, 224-280)
Illegal commands are logged (282-284) and kept in `illegal`. Writes that fail are
kept in `write_errors` (Java prints their stack trace, 192-194). A client that
closed its end before the broker acted on its CLOSE is kept in `early_closes`
(the real broker then writes into a dead socket: "broken pipe").
Controls: `drop_all()` cuts every connection (the broker crashed), `stop()` /
`start()` on the same port, `inject(name, raw)` writes raw bytes to a client,
`close_linger_s` how long the broker takes to act on a CLOSE, `read_lag_s` a busy
broker's pause after each command (bytes then wait unread in its socket).
"""

from __future__ import annotations

import json
import logging
import socket
import threading
import time
from dataclasses import dataclass, field

from robot_doubles.javaish import JavaNameFilter, java_parse_int, java_split_space, java_trim

log = logging.getLogger("doubles.iristk_broker")
NONE = JavaNameFilter("")


@dataclass
class BrokerClient:
    sock: socket.socket
    ticket: str | None = None
    name: str | None = None
    subscribes: JavaNameFilter = field(default_factory=lambda: NONE)
    latest: str | None = None  # the last SUBSCRIBE union written to it
    zombie: bool = False


@dataclass(frozen=True)
class Relayed:
    sender: str
    name: str
    declared: int  # the n the sender wrote
    payload: bytes  # the n bytes read


class _Lines:
    """ParsedInputStream over a socket: readTo(10, 13) and read(n)."""

    def __init__(self, sock: socket.socket) -> None:
        self.stream = sock.makefile("rb", buffering=0)
        self.buffer = bytearray()
        self.eof = False

    def _fill(self) -> bool:
        data = self.stream.read(65536)
        if not data:
            self.eof = True
            return False
        self.buffer += data
        return True

    def line(self) -> str | None:
        """A line (None at EOF with nothing read: Java would return "" for ever)."""
        while True:
            cut = min((i for i in (self.buffer.find(b"\n"), self.buffer.find(b"\r")) if i >= 0), default=-1)
            if cut >= 0:
                raw = bytes(self.buffer[:cut])
                del self.buffer[:cut + 1]
                return raw.decode("utf-8", "replace")
            if self.eof or not self._fill():
                if self.buffer:
                    raw = bytes(self.buffer)
                    self.buffer.clear()
                    return raw.decode("utf-8", "replace")
                return None

    def read(self, n: int) -> bytes | None:
        while len(self.buffer) < n:
            if self.eof or not self._fill():
                return None
        data = bytes(self.buffer[:n])
        del self.buffer[:n]
        return data


class IrisTKBroker:
    def __init__(self, port: int = 0, close_linger_s: float = 0.05, read_lag_s: float = 0.0) -> None:
        self.port = port
        self.close_linger_s = close_linger_s
        self.read_lag_s = read_lag_s  # a busy broker: this long per command before it reads the next
        self.systems: dict[str, list[BrokerClient]] = {}
        self.events: list[Relayed] = []  # every event a connected client sent, in arrival order
        self.illegal: list[tuple[str, str]] = []  # (client name or "unconnected", the logged message)
        self.ignored: list[tuple[str, str]] = []  # lines the broker silently ignores
        self.connects: list[tuple[str, str]] = []  # (ticket, name) of every CONNECT accepted
        self.subscribes: list[tuple[str, str]] = []  # (name, pattern) of every SUBSCRIBE accepted
        self.closes: list[str] = []  # names of the clients that said CLOSE
        self.early_closes: list[str] = []  # ... and had closed their end before the broker acted on it
        self.write_errors: list[tuple[str, str]] = []  # (client name, error) of failed writes
        self._server: socket.socket | None = None
        self._sockets: list[socket.socket] = []
        self._epoch = 0  # drop_all starts a new one: what an old connection still holds is lost
        self._changed = threading.Condition(threading.RLock())

    @property
    def clients(self) -> list[BrokerClient]:
        with self._changed:
            return [c for members in self.systems.values() for c in members]

    # -- lifecycle --------------------------------------------------------------------------
    def start(self) -> "IrisTKBroker":
        server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        server.bind(("127.0.0.1", self.port))
        server.listen(100)
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
        """Every connection cut at once, all state gone (the process died)."""
        with self._changed:
            sockets, self._sockets = self._sockets, []
            self.systems = {}
            self._epoch += 1
            self._changed.notify_all()
        for sock in sockets:
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            sock.close()

    def inject(self, name: str, raw: bytes) -> None:
        for client in [c for c in self.clients if c.name == name]:
            self._write(client, raw)

    def wait_for(self, predicate, timeout: float = 30.0) -> bool:  # a bound, not a measure
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
            with self._changed:
                self._sockets.append(sock)
            threading.Thread(target=self._serve, args=(BrokerClient(sock),), daemon=True).start()

    def _serve(self, client: BrokerClient) -> None:
        lines = _Lines(client.sock)
        epoch = self._epoch
        try:
            while True:
                line = lines.line()
                if epoch != self._epoch:
                    return  # the process died: bytes it had not acted on are gone
                if line is None:  # Java: "" for ever; the client is never removed
                    with self._changed:
                        client.zombie = True
                        self._changed.notify_all()
                    return
                if not self._command(client, line, lines):
                    return
                if self.read_lag_s:
                    time.sleep(self.read_lag_s)
        except OSError:  # connection reset: removeClient (286-288)
            if client.ticket is not None:
                self._remove(client)

    def _command(self, client: BrokerClient, line: str, lines: _Lines) -> bool:
        """One command line (reading an event's bytes); False ends the client's thread."""
        who = client.name or "unconnected"
        if line.startswith("CONNECT "):
            cols = java_split_space(java_trim(line[8:]))
            if len(cols) != 2 or not cols[0] or not cols[1]:
                return self._illegal(who, line)
            with self._changed:
                client.ticket, client.name = cols[0], cols[1]
                self.systems.setdefault(client.ticket, []).append(client)
                self.connects.append((client.ticket, client.name))
                self._update(client.ticket)
                self._write(client, b"CONNECTED\n")
                self._changed.notify_all()
            return True
        if line.startswith("EVENT "):
            cols = java_split_space(java_trim(line[6:]))
            if len(cols) != 2 or not cols[0] or not cols[1]:
                return self._illegal(who, line)
            try:
                length = java_parse_int(cols[1])
            except ValueError:
                return self._illegal(who, line)
            if length < 0 or client.ticket is None:
                return False  # NegativeArraySize / NullPointer: the thread ends (289-291)
            payload = lines.read(length)
            if payload is None:
                return False  # the stream ended inside the event: nothing is relayed
            self._relay(client, cols[0], length, payload)
            return True
        if line.startswith("CLOSE"):
            time.sleep(self.close_linger_s)  # the broker acts on it a little later
            if _peer_gone(client.sock):
                with self._changed:
                    self.early_closes.append(who)
            with self._changed:
                self.closes.append(who)
                self._changed.notify_all()
            if client.ticket is not None:
                self._remove(client)
            try:
                client.sock.close()
            except OSError:
                pass
            return False
        if line.startswith("SUBSCRIBE "):
            pattern = java_trim(line[10:]) or "**"
            try:
                compiled = JavaNameFilter(pattern)
            except ValueError as exc:
                return self._illegal(who, str(exc))
            with self._changed:
                client.subscribes = compiled
                self.subscribes.append((who, pattern))
                if client.ticket is not None:
                    self._update(client.ticket)
                self._changed.notify_all()
            return True
        with self._changed:
            self.ignored.append((who, line[:80]))
            self._changed.notify_all()
        return True

    def _relay(self, sender: BrokerClient, label: str, declared: int, payload: bytes) -> None:
        body = payload.decode("utf-8", "replace").encode() + b"\n"  # new String(bytes) + "\n", getBytes()
        wire = f"EVENT {label} {declared + 1}\n".encode() + body
        with self._changed:
            self.events.append(Relayed(sender.name or "", label, declared, payload))
            self._changed.notify_all()
            receivers = [c for c in self.systems.get(sender.ticket or "", [])
                         if c is not sender and c.subscribes.accepts(label)]
            for receiver in receivers:
                self._write(receiver, wire)

    def _update(self, ticket: str) -> None:
        """updateSubscriptions (121-139): each client gets the union of the others' filters if it changed."""
        members = self.systems.get(ticket, [])
        for target in members:
            union = NONE
            for other in members:
                if other is not target:
                    union = union.combine(other.subscribes)
            text = str(union)
            if target.latest is None or target.latest != text:
                self._write(target, f"SUBSCRIBE {text}\n".encode())
                target.latest = text

    def _remove(self, client: BrokerClient) -> None:
        with self._changed:
            members = self.systems.get(client.ticket or "", [])
            if client in members:
                members.remove(client)
            if not members:
                self.systems.pop(client.ticket or "", None)
            self._update(client.ticket or "")
            for other in self.systems.get(client.ticket or "", []):
                body = json.dumps({"class": "iristk.system.Event", "event_name": "monitor.system.disconnected",
                                   "system": client.name}).encode()
                self._write(other, f"EVENT monitor.system.disconnected {len(body) + 1}\n".encode() + body + b"\n")
            self._changed.notify_all()

    def _illegal(self, who: str, what: str) -> bool:
        log.warning("broker: Illegal Broker command: %s (from %s)", what, who)
        with self._changed:
            self.illegal.append((who, what))
            self._changed.notify_all()
        return True

    def _write(self, client: BrokerClient, data: bytes) -> None:
        try:
            client.sock.sendall(data)
        except OSError as exc:
            with self._changed:
                self.write_errors.append((client.name or "unconnected", str(exc)))
                self._changed.notify_all()


def _peer_gone(sock: socket.socket) -> bool:
    """The client has closed or reset its end (a write now would fail or be lost)."""
    try:
        return sock.recv(1, socket.MSG_PEEK | socket.MSG_DONTWAIT) == b""
    except BlockingIOError:
        return False
    except OSError:
        return True
