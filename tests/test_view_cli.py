"""`pairplay view`'s contract as a user meets it: an output it cannot write, a signal, what it prints.

Before (a new user's trial, 2026-11-30):
- `view --out /proc/x.rrd` said "Failed to create file ... path: /proc/.x.rrd.<pid>.<hex>.tmp" (our
  temporary file, not the user's path) and rerun printed its own "WARN ... Dropping data in
  MemorySink" line: two lines, one naming a file the user never gave.
- an interrupted view saved what it had drawn under the final name and said "saved": a partial
  view claimed to be the complete one.
- a view that ended well printed 3 progress lines on stderr ("drawing ...", the counts, "saved").
Now: one line naming the user's path; a signal keeps the partial view as `<stem>.partial.rrd` (its
event log says it is partial; an existing one stays), exit 128 + signal; one line of result on
stdout, what it does at INFO (-v), what it noticed as a WARNING.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import threading
from pathlib import Path

import msgspec
import numpy as np
import pytest

from pairplay import signals
from pairplay.bench.view import scripted_events
from pairplay.services.view.drive import drive
from pairplay.services.view.output import ViewOutput, finish, open_stream
from pairplay.services.view.readback import read_rrd, segmentation, tensor
from pairplay.services.view.rerun_logger import RerunView

SAMPLE = Path(__file__).resolve().parents[1] / "recordings" / "samples" / "sim-ashley.mcap"


@pytest.mark.parametrize("out", ["/proc/x.rrd", "/proc/self/x/y.rrd", "/sys/x.rrd"])
def test_an_rrd_the_system_refuses_is_one_line_naming_the_users_path_and_nothing_is_left(tmp_path, out, pairplay_cli):
    shutil.copy(SAMPLE, tmp_path / "rec.mcap")
    r = pairplay_cli("view", "--recording", "rec.mcap", "--out", out, cwd=tmp_path)
    assert r.returncode == 2 and r.stdout == "", (r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("pairplay view: ") and lines[0].endswith(")"), r.stderr
    named = lines[0].rsplit(" (", 1)[1][:-1]
    assert named == out or out.startswith(named + "/"), lines[0]  # the file, or the folder that refused it
    assert ".tmp" not in r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec.mcap"]


def _stop_a_paced_view(cwd: Path, sig: signal.Signals, out: str = "v.rrd") -> subprocess.CompletedProcess:
    """A recording viewed at a crawl, signalled once it has drawn (its INFO line with -v, then 1 s)."""
    p = subprocess.Popen([sys.executable, "-m", "pairplay", "view", "--recording", "rec.mcap", "--speed", "0.002",
                          "--out", out, "-v"], cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         env=dict(os.environ, PYTHONUNBUFFERED="1"))
    try:
        first = []
        reader = threading.Thread(target=lambda: first.append(p.stderr.readline()), daemon=True)
        reader.start()
        reader.join(120)
        assert first and "drawing rec.mcap" in first[0], first
        threading.Event().wait(1.0)  # a few events drawn (the paced events are ~20 ms apart here)
        p.send_signal(sig)
        out_text, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    return subprocess.CompletedProcess(p.args, p.returncode, out_text, first[0] + err)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_an_interrupted_view_keeps_a_partial_view_under_a_name_that_says_so(tmp_path, sig):
    shutil.copy(SAMPLE, tmp_path / "rec.mcap")
    (tmp_path / "v.partial.rrd").write_bytes(b"an earlier partial view")  # never replaced without --force
    r = _stop_a_paced_view(tmp_path, sig)
    assert r.returncode == 128 + sig, (r.returncode, r.stdout, r.stderr)
    assert "Traceback" not in r.stderr
    assert r.stdout == ""  # the interrupted line is not a result: stderr, as every verb's
    [line] = [x for x in r.stderr.splitlines() if x.startswith("pairplay view: interrupted (")]
    assert line.startswith(f"pairplay view: interrupted ({signals.said(sig)}) after ") and "before the source ended" in line, line
    assert "saved" not in line and line.endswith("the partial view is in v.partial.2.rrd"), line
    assert not (tmp_path / "v.rrd").exists()  # the complete view's name is not taken by a partial one
    assert (tmp_path / "v.partial.rrd").read_bytes() == b"an earlier partial view"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec.mcap", "v.partial.2.rrd", "v.partial.rrd"]
    texts = [row["TextLog:text"][0] for row in read_rrd(tmp_path / "v.partial.2.rrd")["events"]]
    assert any(f"view stopped by {sig.name}" in t and "this view is partial" in t for t in texts), texts[-3:]


def test_a_view_prints_one_line_of_result_and_its_steps_only_with_verbose(tmp_path, pairplay_cli):
    shutil.copy(SAMPLE, tmp_path / "rec.mcap")
    r = pairplay_cli("view", "--recording", "rec.mcap", cwd=tmp_path)
    assert r.returncode == 0 and r.stderr == "", r.stderr
    assert r.stdout.splitlines() == ["saved rec.rrd: 677 events, 0 notes, Q-table logged 5 times"], r.stdout
    r = pairplay_cli("view", "--recording", "rec.mcap", "--out", "v.rrd", "-v", cwd=tmp_path)
    assert r.returncode == 0 and r.stdout.startswith("saved v.rrd: ") and len(r.stdout.splitlines()) == 1
    assert r.stderr.startswith("INFO pairplay.view: drawing rec.mcap"), r.stderr
    # what the view noticed is a WARNING, shown by default; the result is still one line
    data = SAMPLE.read_bytes()
    (tmp_path / "cut.mcap").write_bytes(data[: len(data) // 2])
    r = pairplay_cli("view", "--recording", "cut.mcap", cwd=tmp_path)
    # a cut file lost its session's later events: its view is partial, named so, as a damaged file's (trial28 F4:
    # it was saved as cut.rrd, the complete name)
    [line] = r.stdout.splitlines()
    assert r.returncode == 0 and line.startswith("saved cut.partial.rrd: ") and line.endswith("; partial"), r.stdout
    assert not (tmp_path / "cut.rrd").exists() and (tmp_path / "cut.partial.rrd").exists()
    assert r.stderr.startswith("WARNING pairplay.view: view: recording not whole"), r.stderr
    assert "cut.mcap was truncated: " in r.stderr and "the view is partial (cut.partial.rrd)" in r.stderr, r.stderr


def test_a_recording_closed_before_its_sessions_end_is_viewed_as_partial(tmp_path, pairplay_cli):
    """trial34 B: a recorder stopped mid-session (SIGTERM) closes its file whole but without a SessionEnded; rebuild
    said PARTIAL, the view was saved under the complete name with 0 notes and no word."""
    from rewrite_mcap import rewritten
    rewritten(tmp_path / "stopped.mcap", each=lambda c, m: [] if c.topic.endswith("/SessionEnded") else [m])
    r = pairplay_cli("view", "--recording", "stopped.mcap", cwd=tmp_path)
    [line] = r.stdout.splitlines()
    assert r.returncode == 0 and line.startswith("saved stopped.partial.rrd: ") and line.endswith("; partial"), r.stdout
    assert not (tmp_path / "stopped.rrd").exists()
    assert "stopped.mcap was closed before its session's end (no SessionEnded recorded)" in r.stderr, r.stderr


class Ticks:
    """A clock that moves `step` seconds at each reading."""

    def __init__(self, step: float):
        self.now, self.step = 0.0, step

    def __call__(self) -> float:
        self.now += self.step
        return self.now


def _viewed(path: Path, events, **kw) -> tuple[dict, RerunView]:
    rec, _ = open_stream(ViewOutput(rrd=path))
    view = RerunView(rec, **kw)
    drive(view, ((e, None) for e in events))
    finish(rec)
    return read_rrd(path), view


def test_a_coalescing_view_keeps_every_line_and_point_and_ends_on_the_same_state(tmp_path):
    """The live view's coalescing (draw at most every interval) against drawing every event."""
    events, q = scripted_events(rounds=3, seed=9, session="co")
    every, _ = _viewed(tmp_path / "every.rrd", events)
    coalesced, view = _viewed(tmp_path / "co.rrd", events, draw_interval_s=0.05, clock=Ticks(0.001))
    assert 0 < view.draws < len(events) / 10
    assert len(coalesced["board/cells"]) < len(every["board/cells"]) / 10
    for path in ("events", "learning/reward", "learning/picks_per_round", "learning/schedule/epsilon"):
        keep = lambda rows: [(r.get("event"), r.get("round"), r.get("session_time"),  # noqa: E731
                              r.get("TextLog:text") or r.get("Scalars:scalars")) for r in rows]
        assert keep(coalesced[path]) == keep(every[path]), path
    assert np.array_equal(tensor(coalesced["q/table"][-1]["Tensor:data"]), q)
    last = lambda rows: segmentation(rows["board/cells"][-1]["SegmentationImage:buffer"],  # noqa: E731
                                     rows["board/cells"][-1]["SegmentationImage:format"])
    assert np.array_equal(last(coalesced), last(every))
    assert coalesced["suggestion"][-1]["TextDocument:text"] == every["suggestion"][-1]["TextDocument:text"]
    # a clock that never reaches the interval: everything is drawn once, at the end, and nothing is lost
    once, view = _viewed(tmp_path / "once.rrd", events, draw_interval_s=10.0, clock=lambda: 0.0)
    assert view.draws == 1 and len(once["events"]) == len(every["events"])
    assert np.array_equal(tensor(once["q/table"][-1]["Tensor:data"]), q)


def test_a_hostile_stamp_loses_no_line_of_the_batch_it_is_sent_in(tmp_path):
    """Lines and points go in columns: one NaT stamp (INT64_MIN) among them must not make rerun refuse
    the whole batch (it said "Time columns had nulls" and dropped every row of the call)."""
    events, _ = scripted_events(rounds=1, seed=10, session="nat")
    events[5] = msgspec.structs.replace(events[5], time_ns=-2**63)
    rows, _ = _viewed(tmp_path / "nat.rrd", events, draw_interval_s=10.0, clock=lambda: 0.0)
    assert len(rows["events"]) > len(events) / 2  # QUpdated has no line
    every, _ = _viewed(tmp_path / "every.rrd", events)
    assert [r["TextLog:text"] for r in rows["events"]] == [r["TextLog:text"] for r in every["events"]]


def test_the_live_views_drawing_thread_yields_the_cpu_and_gets_its_priority_back():
    from pairplay.services.view.drive import lowered_priority

    tid = threading.get_native_id()
    before = os.getpriority(os.PRIO_PROCESS, tid)
    release = threading.Event()
    started_before = threading.Thread(target=lambda: release.wait(5))
    started_before.start()  # as the bus's receive threads: started before, they keep their priority
    with lowered_priority(5):
        inside = os.getpriority(os.PRIO_PROCESS, tid)
        assert os.getpriority(os.PRIO_PROCESS, started_before.native_id) == before
    release.set()
    started_before.join()
    assert inside == min(19, before + 5)
    if os.geteuid() == 0:  # raising it back needs CAP_SYS_NICE
        assert os.getpriority(os.PRIO_PROCESS, tid) == before
        with lowered_priority(0):
            assert os.getpriority(os.PRIO_PROCESS, tid) == before
