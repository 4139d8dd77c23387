"""The verbs that read a recording read it as rebuild does (issue 16): streamed (reader.fold_log), not whole.

Before, verify, view, counterfactual and a study's report read every record of a file into a list, then every event
and its bytes (reader.read_any_log): a 5,000-round recording's verify peaked at 1.6 GB. Now each is given the events
a chunk's at a time (reader.stream_log) and keeps what it folds (the report: counts; verify: the events alone, which
it needs all at once); a file a stream cannot judge (a lost part, a message that does not decode, a seq read twice,
no session) is read whole, as before. What each verb makes is the same either way. Real recordings (the samples),
real damage (damageutil, rewrite_mcap); the memory is tracemalloc's peak, no time is asserted.
"""

from __future__ import annotations

import dataclasses
import tracemalloc
from pathlib import Path

import pytest

from pairplay.replay import reader
from pairplay.replay.reader import NotStreamed, read_any_log

from damageutil import damage, small_chunked_session
from rewrite_mcap import rewritten

SAMPLES = Path(__file__).resolve().parents[1] / "recordings" / "samples"
MANY = SAMPLES / "sim-helmut-fmt2.mcap"  # the samples' longest session


def peak_of(work) -> int:
    """tracemalloc's peak while `work()` runs (run once before: imports and caches are not counted)."""
    work()
    tracemalloc.start()
    try:
        work()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def whole_only(monkeypatch) -> None:
    """Every stream refused: the verbs read each file whole, as before."""
    def refused(path, only, each):
        raise NotStreamed(path)
    monkeypatch.setattr(reader, "stream_log", refused)


def lost_part(path):
    small_chunked_session(path, "lost")
    damage(path, "chunk")


def undecodable(path):
    small_chunked_session(path, "bad")
    damage(path, "undecodable")


def copies(path):
    rewritten(path, each=lambda channel, message: [message, message])


def files(tmp_path) -> list[Path]:
    """The samples and files a stream cannot judge (each read whole)."""
    made = []
    for make in (lost_part, undecodable, copies):
        made.append(tmp_path / f"{make.__name__}.mcap")
        make(made[-1])
    return [SAMPLES / n for n in ("sim-helmut-fmt2.mcap", "sim-ashley.mcap", "human-board-fmt2.mcap",
                                  "console-fmt2.mcap")] + made


# -- verify ---------------------------------------------------------------------------------------------------------

def test_verify_holds_the_events_not_the_files_records_and_bytes():
    # verify read the file whole (its records, then every event and its bytes): its peak was above the whole read's
    # (18.5x the file's size here); it keeps the events alone now (8.4x)
    from pairplay.services.verify import verify_recording

    verified = peak_of(lambda: verify_recording(MANY))
    whole = peak_of(lambda: read_any_log(MANY))
    assert verified < 0.7 * whole, (verified, whole)


def test_verify_says_of_a_file_streamed_what_it_says_of_it_read_whole(tmp_path, monkeypatch):
    from pairplay.services.verify import verify_recording

    paths = files(tmp_path)
    streamed = [dataclasses.asdict(verify_recording(p)) for p in paths]
    whole_only(monkeypatch)
    assert streamed == [dataclasses.asdict(verify_recording(p)) for p in paths]

