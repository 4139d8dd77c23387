"""Rebuild folds a recording's events as they are read: it holds a chunk's records, not the file's (issue 16).

Before, the reader made a list of every record of the file and of every event, kept the first bytes of each
(session, source, seq), and rebuild went over the events five times: a 5,000-round recording's rebuild was
0.61-0.75x a bare StreamReader pass over it (the goal is 0.8x) and peaked at 756 MiB. Now reader.stream_log gives
a file's events to the fold a chunk's at a time and keeps none; a file it cannot read so (a part or a message
lost: where is known only at its end; a seq read twice; no session) is read whole, as before. What is made is the
same either way: the EventLog, field for field but for its events, and rebuild's policy, curve and words. Real
recordings (the samples, a real session's), real damage (damageutil, rewrite_mcap).
"""

from __future__ import annotations

import dataclasses
import tracemalloc
from pathlib import Path

import pytest

from pairplay.replay import rebuild as rb
from pairplay.replay.reader import NotStreamed, read_any_log, stream_log
from pairplay.replay.rebuild import CURVE_READS, curve_rows, rebuild_recording

from damageutil import copies, lost_part, undecodable
from rewrite_mcap import rewritten

SAMPLES = Path(__file__).resolve().parents[1] / "recordings" / "samples"


def fields(log) -> dict:
    """Every field of an EventLog but its events, dicts as their items in order (the order is said: `gaps`)."""
    return {f.name: (list(v.items()) if isinstance(v := getattr(log, f.name), dict) else v)
            for f in dataclasses.fields(log) if f.name != "events"}


def said(rebuilt) -> tuple:
    """What rebuild makes of a file: its policy and curve, and every word it says of the file."""
    return (rebuilt.policy, curve_rows(rebuilt.fold, rebuilt.damaged_rounds), rebuilt.partial, rebuilt.lost,
            rebuilt.damage_read, rebuilt.note, rebuilt.damaged_rounds, rebuilt.started, rebuilt.fold.counts)


def test_rebuild_holds_a_chunk_of_the_file_not_all_of_it():
    # every record, every event and the first bytes of each seq were kept: a rebuild's peak was 13.9x its file's
    # size here (16x for a 300-round session's, 756 MiB for a 5,000-round one's); now the file's bytes and a chunk's
    path = SAMPLES / "sim-helmut-fmt2.mcap"
    rebuild_recording(path)  # (imports, caches)
    tracemalloc.start()
    try:
        rebuild_recording(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 7 * path.stat().st_size, (peak, path.stat().st_size)


@pytest.mark.parametrize("name", ["sim-helmut-fmt2.mcap", "sim-ashley.mcap", "human-board-fmt2.mcap",
                                  "console-fmt2.mcap"])
def test_a_file_streamed_is_read_as_a_file_read_whole(name):
    path = SAMPLES / name
    given = []
    streamed = stream_log(path, CURVE_READS, given.extend)
    whole = read_any_log(path, CURVE_READS)
    assert given == whole.events and streamed.events == []
    assert fields(streamed) == fields(whole)


def test_a_cut_file_is_streamed_as_read_whole(tmp_path):
    data = (SAMPLES / "sim-helmut-fmt2.mcap").read_bytes()
    for k in (5, 8, 11):  # cut in the data section (or its summary): a cut alone loses no part
        path = tmp_path / f"cut{k}.mcap"
        path.write_bytes(data[:len(data) * k // 12])
        given = []
        try:
            streamed = stream_log(path, CURVE_READS, given.extend)
        except NotStreamed:  # the bytes before the cut hold a part that does not read: read whole
            continue
        whole = read_any_log(path, CURVE_READS)
        assert streamed.truncated and given == whole.events and fields(streamed) == fields(whole)


def test_a_repeated_channel_record_and_the_summary_order_the_channels_as_read_whole(tmp_path):
    # each chunk names its channels again (the Go tool's files): the summary's come first, as read whole
    path = rewritten(tmp_path / "repeated.mcap", repeat_channels=True, chunk_size=4096)
    given = []
    streamed = stream_log(path, CURVE_READS, given.extend)
    whole = read_any_log(path, CURVE_READS)
    assert given == whole.events and fields(streamed) == fields(whole)


@pytest.mark.parametrize("make", [lost_part, undecodable, copies])
def test_what_a_stream_cannot_judge_is_read_whole_and_rebuilt_as_before(tmp_path, make, monkeypatch):
    # where a lost part's or a bad message's events were, and whether a seq read again is a copy, is known only
    # from what came before and after: such a file is read whole, and rebuilt from that read
    path = tmp_path / "file.mcap"
    make(path)
    with pytest.raises(NotStreamed):
        stream_log(path, CURVE_READS, lambda events: None)
    streamed_or_not = said(rebuild_recording(path))
    monkeypatch.setattr(rb, "_streamed", _refused)
    assert said(rebuild_recording(path)) == streamed_or_not


def _refused(path):
    raise NotStreamed(path)


@pytest.mark.parametrize("name", ["sim-helmut-fmt2.mcap", "sim-ashley.mcap", "sim-ashley-fmt2.mcap"])
def test_a_file_rebuilt_as_it_is_read_is_rebuilt_as_read_whole(name, monkeypatch):
    path = SAMPLES / name
    streamed = rebuild_recording(path)
    monkeypatch.setattr(rb, "_streamed", _refused)
    whole = rebuild_recording(path)
    assert said(streamed) == said(whole)
