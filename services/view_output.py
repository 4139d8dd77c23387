"""Where the view goes: a saved .rrd always, a served web viewer or a native viewer on request.

Rule: the default output is a file and nothing listens on the network. Every
output is a rerun sink of one RecordingStream, so the file, the web viewer and
the native viewer show the same data with the same blueprint.
- `--serve`: rerun's gRPC server, bound to 127.0.0.1 (GrpcServerSink's
  bind_ip), and rerun's web-viewer page server. The page server has no bind
  option in rerun 0.41: it listens on all interfaces, but it only hands out the
  viewer's HTML/JS/wasm; the data stays on the loopback gRPC port, so a remote
  browser gets an empty viewer. To watch from another machine, forward both
  ports over SSH.
- `--spawn`: rerun's native viewer as a child process (needs a display).

Usage analytics: the SDK calls in this process never load rerun's analytics
(measured: no analytics config or data appears under $HOME). The native viewer
does; rerun's pipeline (re_analytics, native/pipeline.rs) sends nothing when
the environment variable CI is set and FORCE_RERUN_ANALYTICS is not, so the
viewer we spawn gets that environment unless `--rerun-analytics` is given. The
user's own rerun settings (`rerun analytics disable`) are never rewritten.
The web viewer runs in the browser; what it sends is up to the browser's
network (see docs/view.md).
"""

from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass
from pathlib import Path

import rerun as rr

from .view_rerun import APP_ID, blueprint

DEFAULT_GRPC_PORT = 9876  # rerun's defaults
DEFAULT_WEB_PORT = 9090


@dataclass
class ViewOutput:
    rrd: Path | None
    serve: bool = False
    spawn: bool = False
    grpc_port: int = DEFAULT_GRPC_PORT
    web_port: int = DEFAULT_WEB_PORT
    rerun_analytics: bool = False  # True: leave rerun's analytics to the user's own settings


@contextlib.contextmanager
def analytics_off_for_children(enabled: bool = True):
    """Environment for processes started inside: rerun analytics off (see module rule)."""
    if not enabled:
        yield
        return
    saved = {k: os.environ.get(k) for k in ("CI", "FORCE_RERUN_ANALYTICS")}
    os.environ["CI"] = os.environ.get("CI") or "1"
    os.environ.pop("FORCE_RERUN_ANALYTICS", None)
    try:
        yield
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


def open_stream(out: ViewOutput, recording_name: str = "") -> tuple[rr.RecordingStream, list[str]]:
    """A RecordingStream with the requested sinks; returns it and lines saying where it goes."""
    rec = rr.RecordingStream(APP_ID)
    sinks: list = []
    where: list[str] = []
    if out.rrd is not None:
        out.rrd.parent.mkdir(parents=True, exist_ok=True)
        sinks.append(rr.FileSink(str(out.rrd)))
        where.append(f"saving {out.rrd}")
    if out.spawn:
        with analytics_off_for_children(not out.rerun_analytics):
            rr.spawn(port=out.grpc_port, connect=False, hide_welcome_screen=True)
        sinks.append(rr.GrpcSink(f"rerun+http://127.0.0.1:{out.grpc_port}/proxy"))
        where.append(f"native viewer on port {out.grpc_port}")
    if out.serve:
        server = rr.GrpcServerSink(bind_ip="127.0.0.1", port=out.grpc_port)
        sinks.append(server)
        rr.serve_web_viewer(web_port=out.web_port, open_browser=False, connect_to=server.uri)
        where.append(f"web viewer: http://127.0.0.1:{out.web_port}/?url={server.uri}"
                     f" (data on 127.0.0.1:{out.grpc_port} only; the page server listens on all interfaces)")
    if not sinks:
        raise ValueError("the view needs an output: an .rrd path, --serve or --spawn")
    rec.set_sinks(*sinks, default_blueprint=blueprint())
    if recording_name:
        rec.send_recording_name(recording_name)
    return rec, where


def finish(rec: rr.RecordingStream) -> None:
    """Flush and drop the sinks, so a saved .rrd gets its footer (rerun's index)."""
    rec.flush()
    rec.disconnect()
