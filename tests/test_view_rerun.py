"""`pairplay view` end to end: a recording or the live bus in, an .rrd out, read back by rerun."""

import os
import subprocess
import sys
import threading
import time
from pathlib import Path


import numpy as np

from pairplay.schemas import events as ev
from pairplay.schemas.events import encode_event
from pairplay.schemas.envelope import tag_of
from pairplay.schemas.keys import event_key
from pairplay.services.bus import BusOptions, open_bus
from pairplay.cli.main import main
from pairplay.bench.view import scripted_events, write_recording
from pairplay.services.view.drive import drive
from pairplay.services.view.model import Cell
from pairplay.services.view.output import ViewOutput, finish, open_stream, viewer_environment
from pairplay.services.view.readback import has_blueprint, read_rrd, segmentation, tensor
from pairplay.services.view.rerun_logger import RerunView
from pairplay.services.view.sources import LiveSource

ENTITIES = {"board/cells", "board/faces", "board/observed", "board/match", "board/candidates", "suggestion",
            "q/table", "learning/reward", "learning/schedule/epsilon", "learning/schedule/alpha",
            "learning/schedule/psi", "learning/picks_per_round", "session", "events"}


def cells_at(rows, event_index):
    """The board image logged last at or before the view's event number `event_index`."""
    row = [r for r in rows["board/cells"] if r.get("event") is not None and r["event"] <= event_index][-1]
    return segmentation(row["SegmentationImage:buffer"], row["SegmentationImage:format"])


def test_a_recording_viewed_saves_an_rrd_that_rerun_reads_back_with_board_suggestion_and_q(tmp_path):
    events, q = scripted_events(rounds=2, seed=5, session="rec1")
    mcap = write_recording(events, tmp_path / "rec1.mcap")
    assert main(["view", "--recording", str(mcap)]) == 0
    rrd = tmp_path / "rec1.rrd"  # the default: next to the recording
    rows = read_rrd(rrd)
    assert ENTITIES <= set(rows) and has_blueprint(rrd)
    # the board: view event n is events[n - 1]; after the first reveal that card is face up
    first = next(i for i, e in enumerate(events) if isinstance(e, ev.CardRevealed))
    assert cells_at(rows, first + 1).flat[events[first].card] == Cell.FACE_UP
    assert (cells_at(rows, len(events)) == Cell.MATCHED).all()
    # a suggestion in words
    made = next(e for e in events if isinstance(e, ev.SuggestionMade))
    texts = [r["TextDocument:text"][0] for r in rows["suggestion"]]
    assert any(f"action {made.action}:" in t and "speech:" in t and "head:" in t for t in texts)
    # the Q-table: rate-limited, and the last one equals the learner's
    n_updates = sum(isinstance(e, ev.QUpdated) for e in events)
    assert 1 <= len(rows["q/table"]) < n_updates
    assert np.array_equal(tensor(rows["q/table"][-1]["Tensor:data"]), q)
    assert [r["Scalars:scalars"][0] for r in rows["learning/picks_per_round"]] == [
        2 * e.turns for e in events if isinstance(e, ev.RoundEnded)]


def test_a_corrupt_recording_is_shown_up_to_the_cut_and_said_so(tmp_path):
    from pairplay.replay.mcapscan import scan
    from pairplay.replay.writer import EventLogWriter

    events, _ = scripted_events(rounds=1, seed=6, session="cut")
    mcap = tmp_path / "cut.mcap"
    writer = EventLogWriter(mcap, chunk_size=2048)  # small chunks: a cut in the last loses its events only
    for e in events:
        writer.write(event_key(e.session, e.source, tag_of(type(e))), encode_event(e), log_time_ns=e.time_ns)
    writer.close()
    data = mcap.read_bytes()
    last = scan(mcap).chunks[-1]
    # cut inside the last chunk: its events are lost (half the file fell after the Data End in a small recording,
    # a cut that lost no message, which a view shows whole)
    mcap.write_bytes(data[: last.offset + last.length // 2])
    out = tmp_path / "cut.rrd"
    assert main(["view", "--recording", str(mcap), "--out", str(out)]) == 0
    # a cut file lacks its session's later events: its view is partial, named so (trial28 F4)
    assert not out.exists()
    rows = read_rrd(tmp_path / "cut.partial.rrd")
    notes = [r["TextLog:text"][0] for r in rows["events"]]
    assert any("recording not whole" in n for n in notes), notes


def _publish(bus, events):
    encode = encode_event
    for e in events:
        bus.put(event_key(e.session, e.source, tag_of(type(e))), encode(e))


def _wait_matching(bus, key, timeout=10.0):
    deadline = time.monotonic() + timeout
    while not bus.matching(key):
        assert time.monotonic() < deadline, "the view never subscribed"
        time.sleep(0.02)


def test_a_live_session_on_the_bus_is_viewed_to_the_end_and_bad_messages_are_noted(tmp_path):
    events, q = scripted_events(rounds=1, seed=7, session="live1")
    rrd = tmp_path / "live1.rrd"
    with open_bus() as session_bus:
        endpoint = session_bus.locators()[0]
        with open_bus(BusOptions(listen=[], connect=[endpoint])) as view_bus:
            rec, _ = open_stream(ViewOutput(rrd=rrd))
            view = RerunView(rec)
            source = LiveSource(view_bus, "live1")
            stop = threading.Event()
            result = {}
            viewer = threading.Thread(target=lambda: result.update(s=drive(view, source.items(stop, grace_s=0.3))))
            viewer.start()
            first_key = event_key("live1", events[0].source, tag_of(type(events[0])))
            _wait_matching(session_bus, first_key)
            _publish(session_bus, events[:5])
            session_bus.put("pairplay/live1/game/CardRevealed", b'{"type": "CardRevealed", "card": "nine"}')
            _publish(session_bus, events[5:])
            viewer.join(timeout=30)
            stop.set()
            assert not viewer.is_alive()
            finish(rec)
    assert result["s"].events == len(events) and result["s"].notes == 1
    rows = read_rrd(rrd)
    assert np.array_equal(tensor(rows["q/table"][-1]["Tensor:data"]), q)
    assert any("malformed message on pairplay/live1/game/CardRevealed" in r["TextLog:text"][0] for r in rows["events"])


def test_serving_binds_the_data_port_and_the_page_to_loopback_only(tmp_path):
    """Nothing listens beyond loopback unless configured: rerun's own page server (`rr.serve_web_viewer`)
    listened on all interfaces (0.0.0.0:9090); `--serve` now runs `rerun --serve-web --bind 127.0.0.1`."""
    import socket
    import urllib.request

    ports = []
    for _ in range(2):
        s = socket.socket()
        s.bind(("127.0.0.1", 0))
        ports.append(s.getsockname()[1])
        s.close()

    def listening() -> set[str]:
        lines = Path("/proc/net/tcp").read_text().splitlines()[1:] + Path("/proc/net/tcp6").read_text().splitlines()[1:]
        return {line.split()[1] for line in lines if line.split()[3] == "0A"}  # state LISTEN
    rec, where = open_stream(ViewOutput(rrd=tmp_path / "s.rrd", serve=True, grpc_port=ports[0], web_port=ports[1]))
    try:
        local = listening()
        for port in ports:
            assert f"0100007F:{port:04X}" in local  # 127.0.0.1
            assert not any(a.endswith(f":{port:04X}") and not a.startswith("0100007F") for a in local), (port, local)
        assert any(f"http://127.0.0.1:{ports[1]}/" in w for w in where)
        with urllib.request.urlopen(f"http://127.0.0.1:{ports[1]}/", timeout=10) as page:
            assert page.status == 200 and b"<html" in page.read().lower()
        rec.log("events", __import__("rerun").TextLog("served"))
    finally:
        finish(rec)
    assert not {f"0100007F:{port:04X}" for port in ports} & listening()  # stopped with the view
    assert (tmp_path / "s.rrd").stat().st_size > 0


def test_rerun_analytics_stay_off(tmp_path):
    # a viewer the view starts gets rerun's off switch; --rerun-analytics leaves the environment alone
    env = {"HOME": "/h", "FORCE_RERUN_ANALYTICS": "1"}
    assert viewer_environment(env) == {"HOME": "/h", "CI": "1"}
    assert viewer_environment(env, analytics_off=False) == env
    # the view process itself never loads rerun's analytics: nothing appears under a fresh HOME
    events, _ = scripted_events(rounds=1, seed=8, session="quiet")
    mcap = write_recording(events, tmp_path / "quiet.mcap")
    home = tmp_path / "home"
    home.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("XDG_CONFIG_HOME", "XDG_DATA_HOME")}
    env["HOME"] = str(home)
    subprocess.run([sys.executable, "-m", "pairplay", "view", "--recording", str(mcap)], env=env, check=True,
                   capture_output=True, timeout=120)
    assert (tmp_path / "quiet.rrd").is_file()
    assert not list(home.rglob("*"))


def test_a_real_session_on_the_bus_with_the_view_attached_gives_the_learners_q_table(tmp_path):
    """`pairplay session`'s own runner (game, learner, simulated participant, recorder) with the
    view watching from its own Zenoh session; then the recording viewed gives the same view."""
    from pairplay.schemas.session import SessionConfig
    from pairplay.services.session import run_session

    config = SessionConfig(session="real1", participant="sim:tatiana", persona="tatiana", seed=11, rounds=3)
    live_rrd = tmp_path / "live.rrd"
    stop = threading.Event()
    attached = {}

    def attach_view(services_bus):
        view_bus = open_bus(BusOptions(listen=[], connect=[services_bus.locators()[0]]))
        rec, _ = open_stream(ViewOutput(rrd=live_rrd))
        source = LiveSource(view_bus, "real1")
        summary = {}
        viewer = threading.Thread(target=lambda: summary.update(s=drive(RerunView(rec), source.items(stop))))
        viewer.start()
        probe = services_bus.session.declare_publisher(event_key("real1", "game", "SessionStarted"))
        deadline = time.monotonic() + 10
        while not probe.matching_status.matching:  # the view's subscription has reached the session
            assert time.monotonic() < deadline
            time.sleep(0.02)
        probe.undeclare()
        attached.update(bus=view_bus, rec=rec, viewer=viewer, summary=summary)

    nodes = {}
    mcap = run_session(config, tmp_path / "real1.mcap", on_bus=attach_view, nodes_out=nodes)
    attached["viewer"].join(timeout=60)
    assert not attached["viewer"].is_alive()
    finish(attached["rec"])
    attached["bus"].close()
    learner_q = nodes["learner"].logic.learner.q[0]
    assert learner_q.any()
    live = read_rrd(live_rrd)
    assert np.array_equal(tensor(live["q/table"][-1]["Tensor:data"]), learner_q)
    assert (cells_at(live, attached["summary"]["s"].events) == Cell.MATCHED).all()
    assert len(live["learning/picks_per_round"]) == 3
    assert any("speech:" in r["TextDocument:text"][0] for r in live["suggestion"])
    # the same session from its recording: the same Q-table and the same boards, event by event
    assert main(["view", "--recording", str(mcap)]) == 0
    replayed = read_rrd(mcap.with_suffix(".rrd"))
    assert np.array_equal(tensor(replayed["q/table"][-1]["Tensor:data"]), learner_q)
    boards = lambda rows: [r["SegmentationImage:buffer"] for r in rows["board/cells"]]  # noqa: E731
    assert boards(replayed) == boards(live)


def test_a_view_that_joins_a_running_session_catches_up_from_the_recorder(tmp_path):
    from pairplay.services.recorder import Recorder

    events, q = scripted_events(rounds=2, seed=12, session="late1")
    half = len(events) // 2
    stop = threading.Event()
    with open_bus() as session_bus:
        recorder = Recorder(session_bus, "late1", tmp_path / "late1.mcap")
        recorder.start()
        recorder_thread = threading.Thread(target=recorder.run, args=(stop,))
        recorder_thread.start()
        _publish(session_bus, events[:half])
        deadline = time.monotonic() + 10
        while recorder.writer.count < half:  # the first half is in the recorder's log
            assert time.monotonic() < deadline
            time.sleep(0.02)
        with open_bus(BusOptions(listen=[], connect=[session_bus.locators()[0]])) as view_bus:
            view = RerunView(open_stream(ViewOutput(rrd=tmp_path / "late1.rrd"))[0])
            source = LiveSource(view_bus, "late1")
            assert len(source.backlog) == half
            result = {}
            viewer = threading.Thread(target=lambda: result.update(s=drive(view, source.items(stop, grace_s=0.3))))
            viewer.start()
            _wait_matching(session_bus, event_key("late1", events[half].source, tag_of(type(events[half]))))
            _publish(session_bus, events[half:])
            viewer.join(timeout=30)
            stop.set()
            finish(view.rec)
        recorder_thread.join(timeout=10)
        recorder.close()
    assert result["s"].events == len(events)  # each event once: the log, then live, no repeats
    assert np.array_equal(view.model.q, q) and not view.model.q_partial


def test_a_view_that_joins_a_session_under_way_with_no_recorder_says_what_it_missed(tmp_path):
    """A new user's trial: `pairplay view --session S --connect` attached to a replay already under way saved
    "live.rrd: 2547 events" of 2552, the session's first five (its start among them) missed without a word.
    Each source's seq starts at 1: a source first seen above it lost its first events. The view notes them,
    names its .rrd partial (never passed off as whole) and says so: each source's loss on stderr, the
    saved line on stdout. A real `pairplay view`
    process on a real bus; the first events are published before it subscribes (nobody hears them)."""
    events, q = scripted_events(rounds=1, seed=7, session="join1")
    early = 5
    with open_bus() as session_bus:
        _publish(session_bus, events[:early])  # no subscriber yet: gone, as a replay's start before the view
        view = subprocess.Popen([sys.executable, "-m", "pairplay", "view", "--session", "join1", "--connect",
                                 session_bus.locators()[0], "--out", "join1.rrd"], cwd=tmp_path,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            _wait_matching(session_bus, event_key("join1", events[early].source, tag_of(type(events[early]))),
                           timeout=300)
            _publish(session_bus, events[early:])
            out, err = view.communicate(timeout=300)
        finally:
            if view.poll() is None:
                view.kill()
                view.wait()
    partial = tmp_path / "join1.partial.rrd"
    missed = (f"{early} events of the session never reached the view (published before it joined, with no "
              "recorder's log to catch up from, or dropped); see its notes")
    assert view.returncode == 0, err
    assert out.startswith(f"saved {partial.name}: {len(events) - early} events") and out.rstrip().endswith(
        f"; partial: {missed}"), out
    lines = err.splitlines()  # each source's loss, as noted (a WARNING, -q or not)
    assert len(lines) == 2 and all("missing before seq" in n and "published before the view joined" in n
                                   for n in lines), err
    assert partial.exists() and not (tmp_path / "join1.rrd").exists()
    texts = [r["TextLog:text"][0] for r in read_rrd(partial)["events"]]
    assert any("missing before seq" in t and "published before the view joined" in t for t in texts), texts
