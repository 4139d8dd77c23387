"""Where the view goes: a saved .rrd always, a served web viewer or a native viewer on request.

Rule: the default output is a file and nothing listens on the network. Every
output is a rerun sink of one RecordingStream, so the file, the web viewer and
the native viewer show the same data with the same blueprint.
- `--serve`: rerun's own server (`rerun --serve-web --bind 127.0.0.1`, the
  wheel's `rerun` program, in a process of its own): its gRPC data port and its
  web-viewer page port both bound to 127.0.0.1; the view sends to it as to a
  native viewer. (The SDK's page server, `rr.serve_web_viewer`, has no bind
  option in rerun 0.41 and listened on all interfaces.) It lives as long as the
  view: `finish` stops it (its process group), and, started from a process
  with no other thread (`pairplay view`), it gets SIGTERM if the view dies
  (Linux's parent-death signal). To watch from another machine, forward both
  ports over SSH.
- `--spawn`: rerun's native viewer as its own process (needs a display),
  started with `--bind 127.0.0.1` so its data port is loopback only too.

Usage analytics: the SDK calls in this process never load rerun's analytics
(measured: no analytics config or data appears under $HOME). The native viewer
does; rerun's pipeline (re_analytics, native/pipeline.rs) sends nothing when
the environment variable CI is set and FORCE_RERUN_ANALYTICS is not, so the
viewer we start gets that environment unless `--rerun-analytics` is given
(measured under Xvfb: with it, the viewer wrote no analytics file under $HOME;
without it, it printed rerun's analytics notice and wrote its analytics config
and an event file). The user's own rerun settings (`rerun analytics disable`)
are never rewritten.
The web viewer runs in the browser; what it sends is up to the browser's
network (see docs/view.md).
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import quote

import rerun as rr

from pairplay.errors import OptionError

from pairplay.services.view import DEFAULT_GRPC_PORT, DEFAULT_WEB_PORT  # noqa: F401 (re-exported)
from pairplay.services.view.rerun_logger import APP_ID, blueprint

SPAWN_TIMEOUT_S = 45.0  # the viewer starts in a few seconds on a quiet machine; >15 s at load 13-15 (a full
# suite beside: test_view_rerun timed out at 15 s), and a researcher's laptop may be as busy


@dataclass
class ViewOutput:
    rrd: Path | None
    serve: bool = False
    spawn: bool = False
    grpc_port: int = DEFAULT_GRPC_PORT
    web_port: int = DEFAULT_WEB_PORT
    rerun_analytics: bool = False  # True: leave rerun's analytics to the user's own settings


def rerun_executable() -> str:
    """The `rerun` viewer of the rerun-sdk wheel: on PATH, or beside this Python (an unactivated venv)."""
    beside = Path(sys.executable).with_name("rerun")
    return shutil.which("rerun") or str(beside)


def _port_open(port: int, timeout_s: float) -> bool:
    """Wait until something accepts connections on 127.0.0.1:port (a stream to nobody blocks)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        with socket.socket() as probe:
            probe.settimeout(0.2)
            if probe.connect_ex(("127.0.0.1", port)) == 0:
                return True
        time.sleep(0.1)
    return False


def viewer_environment(env: dict[str, str], analytics_off: bool = True) -> dict[str, str]:
    """The environment for a rerun viewer we start: rerun's analytics off (see module rule)."""
    env = dict(env)
    if analytics_off:
        env["CI"] = env.get("CI") or "1"
        env.pop("FORCE_RERUN_ANALYTICS", None)
    return env


def spawn_viewer(port: int, analytics_off: bool = True) -> subprocess.Popen:
    """rerun's native viewer, its data port bound to 127.0.0.1, in its own process group
    (Ctrl-C on the view leaves the window open); raises if it does not come up."""
    command = [rerun_executable(), "--bind", "127.0.0.1", "--port", str(port), "--hide-welcome-screen",
               "--expect-data-soon"]
    viewer = subprocess.Popen(command, env=viewer_environment(dict(os.environ), analytics_off),
                              stdin=subprocess.DEVNULL, start_new_session=True)
    deadline = time.monotonic() + SPAWN_TIMEOUT_S
    while not _port_open(port, 0.5):
        if viewer.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(f"rerun's native viewer did not start on 127.0.0.1:{port} (exit code "
                               f"{viewer.poll()}; it needs a display and a GPU driver that can draw R32Float; "
                               "its reason is printed above). Use the saved .rrd or --serve instead.")
    return viewer


_SERVERS: dict[int, subprocess.Popen] = {}  # id(stream) -> the rerun server `--serve` started for it (finish stops it)


def rerun_binary() -> str:
    """The wheel's `rerun` program itself (rerun_cli/rerun): the `rerun` script on PATH is a Python
    wrapper that runs it as a child, so signalling the wrapper left the server listening."""
    try:
        import rerun_cli
        binary = Path(rerun_cli.__file__).with_name("rerun")
        if binary.is_file() and os.access(binary, os.X_OK):
            return str(binary)
    except ImportError:
        pass
    return rerun_executable()


def _die_with_parent() -> None:  # runs in the child between fork and exec: no Python state touched
    import ctypes
    ctypes.CDLL(None, use_errno=True).prctl(1, 15)  # PR_SET_PDEATHSIG, SIGTERM


def serve_viewer(grpc_port: int, web_port: int, analytics_off: bool = True) -> subprocess.Popen:
    """rerun's web viewer and gRPC proxy, both bound to 127.0.0.1 (see module rule), in a process
    group of its own (Ctrl-C goes to the view, which stops it when finished); raises if it does not
    come up within SPAWN_TIMEOUT_S."""
    command = [rerun_binary(), "--serve-web", "--bind", "127.0.0.1", "--port", str(grpc_port),
               "--web-viewer-port", str(web_port), "--hide-welcome-screen"]
    with tempfile.TemporaryFile() as said:  # its log (a pipe nobody reads could fill and stop it)
        server = subprocess.Popen(command, env=viewer_environment(dict(os.environ), analytics_off),
                                  stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=said,
                                  start_new_session=True,
                                  # (a preexec_fn may deadlock a process with other threads: only without them)
                                  preexec_fn=_die_with_parent if sys.platform == "linux"
                                  and threading.active_count() == 1 else None)
        deadline = time.monotonic() + SPAWN_TIMEOUT_S
        while not (_port_open(grpc_port, 0.2) and _port_open(web_port, 0.2)):
            if server.poll() is not None or time.monotonic() > deadline:
                stop_server(server)
                said.seek(0)
                last = [x for x in said.read().decode("utf-8", "replace").splitlines() if x.strip()][-1:]
                raise RuntimeError(f"rerun's web viewer server did not start on 127.0.0.1 ports {grpc_port} and "
                                   f"{web_port} (exit code {server.poll()}{': ' + last[0][:200] if last else ''})")
    return server


def stop_server(server: subprocess.Popen, timeout_s: float = 2.0) -> None:
    """Stop a server `serve_viewer` started: SIGTERM, then SIGKILL after `timeout_s`."""
    def signal_group(sig: int) -> None:  # its group (start_new_session): whatever it started goes too
        try:
            os.killpg(server.pid, sig)
        except ProcessLookupError:
            pass
    if server.poll() is None:
        signal_group(signal.SIGTERM)
        try:
            server.wait(timeout_s)
        except subprocess.TimeoutExpired:
            signal_group(signal.SIGKILL)
            server.wait()


def _free_port() -> int:
    """A port the OS has free on 127.0.0.1 now (for `--web-port 0`/`--grpc-port 0`: any)."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def require_free_port(host: str, port: int, option: str) -> None:
    """OptionError if `host:port` cannot be bound now. rerun's servers bind in a thread of
    their own and only log a failure (then the first flush raises), so we ask first."""
    if port == 0:
        return
    with socket.socket() as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as rerun's listener: TIME_WAIT is fine
        try:
            probe.bind((host, port))
        except OSError as err:
            raise OptionError(f"port {port} on {host} is taken ({err.strerror}); choose another",
                              f"{option} {port}") from None


def open_stream(out: ViewOutput, recording_name: str = "") -> tuple[rr.RecordingStream, list[str]]:
    """A RecordingStream with the requested sinks; returns it and lines saying where it goes.
    OptionError (before anything starts) if a port it needs is taken; OSError naming `out.rrd`
    if the system refuses that file (callers writing through pairplay.outputs.output_path get
    it named with the user's path, not the temporary one)."""
    if out.serve:
        require_free_port("127.0.0.1", out.grpc_port, "--grpc-port")
        require_free_port("127.0.0.1", out.web_port, "--web-port")
    elif out.spawn:
        require_free_port("127.0.0.1", out.grpc_port, "--grpc-port")
    if out.rrd is not None:  # made here first: the system's refusal is an OSError naming the file, and no
        out.rrd.parent.mkdir(parents=True, exist_ok=True)  # stream exists yet to print rerun's own warning
        out.rrd.open("wb").close()
    server, grpc_port, web_port = None, 0, 0
    if out.serve:  # started before the stream's threads exist (its preexec_fn runs between fork and exec)
        grpc_port, web_port = out.grpc_port or _free_port(), out.web_port or _free_port()
        server = serve_viewer(grpc_port, web_port, analytics_off=not out.rerun_analytics)
    try:
        return _stream(out, recording_name, server, grpc_port, web_port)
    except BaseException:
        if server is not None:
            stop_server(server)
        raise


def _stream(out: ViewOutput, recording_name: str, server: subprocess.Popen | None, grpc_port: int,
            web_port: int) -> tuple[rr.RecordingStream, list[str]]:
    rec = rr.RecordingStream(APP_ID)
    sinks: list = []
    where: list[str] = []
    if out.rrd is not None:
        sinks.append(rr.FileSink(str(out.rrd)))  # the caller says where it was saved once it is complete
    if out.spawn:
        spawn_viewer(out.grpc_port, analytics_off=not out.rerun_analytics)
        sinks.append(rr.GrpcSink(f"rerun+http://127.0.0.1:{out.grpc_port}/proxy"))
        where.append(f"native viewer on 127.0.0.1:{out.grpc_port}")
    if server is not None:
        _SERVERS[id(rec)] = server
        uri = f"rerun+http://127.0.0.1:{grpc_port}/proxy"
        sinks.append(rr.GrpcSink(uri))
        where.append(f"web viewer: http://127.0.0.1:{web_port}/?url={quote(uri, safe='')}"
                     f" (page and data on 127.0.0.1 only: ports {web_port} and {grpc_port})")
    if not sinks:
        raise ValueError("the view needs an output: an .rrd path, --serve or --spawn")
    rec.set_sinks(*sinks, default_blueprint=blueprint())
    if recording_name:
        rec.send_recording_name(recording_name)
    return rec, where


def finish(rec: rr.RecordingStream, timeout_s: float = 1e9) -> None:
    """Flush (for at most `timeout_s`: a stopped view takes what its shutdown's deadline leaves) and
    drop the sinks, so a saved .rrd gets its footer (rerun's index)."""
    try:
        rec.flush(timeout_sec=max(timeout_s, 0.0))
        rec.disconnect()
    finally:
        server = _SERVERS.pop(id(rec), None)
        if server is not None:
            stop_server(server, min(max(timeout_s, 0.1), 2.0))
