"""A cut recording whose recorder's journal beside it holds more is said so by every verb that reads it.

A new user's trial: a recording cut by a crash, its `.mcap.journal` beside it holding the rest (the session's
SessionEnded among it), read by `pairplay rebuild` and `replay --verify`: they said PARTIAL, or "PASS as far as
the file goes", and never that the journal holds N more events that `pairplay recover FILE` adds. Each verb now
says it in one line (replay/recover.py `journal_left`), its exit code unchanged; once recovered, the line names
the recovered copy instead; a journal that adds nothing says nothing.
"""

from __future__ import annotations

import pytest

from pairplay.replay.reader import read_log
from pairplay.replay.wal import JournalWriter, wal_path

from pairplay.replay.mcapscan import scan

from damageutil import small_chunked_session


@pytest.fixture(scope="module")
def whole(tmp_path_factory):
    return small_chunked_session(tmp_path_factory.mktemp("left") / "whole.mcap", "left")


def cut_with_journal(whole, tmp_path, name="left.mcap", at=None):
    """A copy of `whole` cut as a crash cuts it (its second half lost) and its recorder's journal beside it,
    holding every event the recorder received (the ones the cut lost, the SessionEnded among them)."""
    path = tmp_path / name
    data = whole.read_bytes()
    path.write_bytes(data[:at or len(data) // 2])  # (its last third: its summary and index, no event)
    records = read_log(whole).events
    j = JournalWriter(path, "left")
    for r in records:
        j.add((r.key, r.payload))
    j.close()
    lacks = len(records) - len(read_log(path).events)
    assert lacks > 0
    return path, lacks


VERBS = [(["rebuild", "{p}", "--no-plot", "--out", "{t}/out"], 0), (["replay", "--verify", "{p}"], 0),
         (["counterfactual", "{p}", "--fit-only", "--out", "{t}/cf"], 0),
         (["view", "--recording", "{p}", "--out", "{t}/v.rrd"], 0)]


@pytest.mark.parametrize("verb,code", VERBS, ids=lambda v: " ".join(v[:2]) if isinstance(v, list) else str(v))
def test_every_verb_reading_a_cut_recording_names_the_journal_that_holds_more(whole, tmp_path, pairplay_cli, verb,
                                                                               code):
    path, lacks = cut_with_journal(whole, tmp_path)
    args = [a.replace("{p}", str(path)).replace("{t}", str(tmp_path)) for a in verb]
    ran = pairplay_cli(*args, cwd=tmp_path)
    assert ran.returncode == code, (ran.stdout, ran.stderr)
    said = [line for line in ran.stderr.splitlines() if "journal" in line]
    assert said == [f"pairplay {verb[0]}: {path}: its recorder's journal {wal_path(path).name} beside it holds "
                    f"{lacks} messages the file lacks, the session's end (SessionEnded) among them: "
                    f"`pairplay recover {path}` adds them (to left.recovered.mcap)"], ran.stderr
    # as the line says: recover adds them, and the line then names the recovered copy
    ran = pairplay_cli("recover", path, cwd=tmp_path)
    assert ran.returncode == 0 and f"{lacks} events taken from its journal" in ran.stdout, (ran.stdout, ran.stderr)
    if verb[0] in ("rebuild", "counterfactual", "view"):
        args.append("--force")
    ran = pairplay_cli(*args, cwd=tmp_path)
    assert ran.returncode == code, (ran.stdout, ran.stderr)
    said = [line for line in ran.stderr.splitlines() if "journal" in line]
    assert said == [f"pairplay {verb[0]}: {path}: its recorder's journal {wal_path(path).name} beside it holds "
                    f"{lacks} messages the file lacks, the session's end (SessionEnded) among them; "
                    f"{tmp_path / 'left.recovered.mcap'} is beside it (`pairplay recover`'s copy with them): give "
                    "that instead"], ran.stderr


def test_a_journal_that_adds_nothing_says_nothing(whole, tmp_path, pairplay_cli):
    """A whole recording beside a stale journal (all of it in the file): nothing is said by the reading verbs
    (recover names a stale journal itself)."""
    path = tmp_path / "left.mcap"
    path.write_bytes(whole.read_bytes())
    j = JournalWriter(path, "left")
    for r in read_log(whole).events[:10]:
        j.add((r.key, r.payload))
    j.close()
    ran = pairplay_cli("replay", "--verify", path, cwd=tmp_path)
    assert ran.returncode == 0 and "journal" not in ran.stderr + ran.stdout, (ran.stdout, ran.stderr)


@pytest.mark.parametrize("verb", [["rebuild", "--no-plot"], ["replay", "--verify"]])
def test_a_cut_file_refused_for_no_whole_round_names_the_journal_in_its_line(whole, tmp_path, pairplay_cli, verb):
    """Cut inside round 1: refused (exit 2, one line) as before, and the line says where the rest of it is."""
    path, lacks = cut_with_journal(whole, tmp_path, at=scan(whole).chunks[1].offset)
    ran = pairplay_cli(*verb, path, cwd=tmp_path)
    assert ran.returncode == 2 and ran.stdout == "", (ran.stdout, ran.stderr)
    [line] = ran.stderr.splitlines()
    assert "holds no whole round: the file is cut before round 1 of 3 ended" in line, line
    assert line.endswith(f"; its recorder's journal left.mcap.journal beside it holds {lacks} messages the file "
                         f"lacks, the session's end (SessionEnded) among them: `pairplay recover {path}` adds them "
                         "(to left.recovered.mcap)"), line


def test_a_copy_whose_journal_gave_back_the_sessions_rest_is_whole(whole, tmp_path, pairplay_cli):
    """What recover completed from a journal read to its end, the session's end among it, is the session whole:
    it was "recovered from a cut file: the events after its cut are lost", its policy partial (and a study game read
    from it had none), though the journal had given back every event the recorder received (reader.journal_restored).
    A journal that did not hold the end leaves the copy partial, as before."""
    path, _ = cut_with_journal(whole, tmp_path)
    assert pairplay_cli("recover", path).returncode == 0
    copy = tmp_path / "left.recovered.mcap"
    ran = pairplay_cli("replay", "--verify", copy)
    assert ran.returncode == 0 and ran.stdout.splitlines()[-1] == "verify: PASS", ran.stdout
    ran = pairplay_cli("rebuild", copy, "--no-plot", "--out", tmp_path / "out")
    assert ran.returncode == 0 and "PARTIAL" not in ran.stderr, ran.stderr
    # the journal without the session's end (it stops where the file does, a few events on): a part, said so
    short = tmp_path / "short"
    short.mkdir()
    data = whole.read_bytes()
    cut = short / "left.mcap"
    cut.write_bytes(data[:len(data) // 2])
    held = len(read_log(cut).events)
    j = JournalWriter(cut, "left")
    for r in read_log(whole).events[:held + 5]:
        j.add((r.key, r.payload))
    j.close()
    assert pairplay_cli("recover", cut).returncode == 0
    ran = pairplay_cli("rebuild", short / "left.recovered.mcap", "--no-plot", "--out", short / "out")
    assert ran.returncode == 0 and "PARTIAL session" in ran.stderr and "the events after its cut are lost" in ran.stderr, \
        ran.stderr
