"""Identical copies of one event in a recording are read once by every verb, and said (replay/reader.py rule).

A hostile user's trial (trial28 F1): a recording whose every message was stored twice (same channel, times,
sequence, bytes) rebuilt with exit 0 into a wrong policy (visits doubled, Q updated twice), not flagged; view drew
twice the events. The files are made here from a frozen sample with the mcap library's own Writer."""

from __future__ import annotations

import json
import shutil

import pytest

from pairplay.cli.main import main
from pairplay.replay.mcapscan import scan
from pairplay.replay.reader import read_log

from rewrite_mcap import SAMPLE, rewritten

TWICE = lambda channel, message: [message, message]  # noqa: E731


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("copies")
    original = d / "orig.mcap"
    shutil.copyfile(SAMPLE, original)
    return {"orig": original,
            "twice": rewritten(d / "twice.mcap", each=TWICE),  # MCAP sequence repeated: mcapscan says so too
            "twice_renumbered": rewritten(d / "twice_renumbered.mcap", each=TWICE, renumber=True)}  # MCAP-whole


def _run(capsys, *argv):
    code = main(list(argv))
    said = capsys.readouterr()
    return code, said.out + said.err


@pytest.mark.parametrize("kind", ["twice", "twice_renumbered"])
def test_the_reader_reads_each_event_once_and_says_the_copies(files, kind):
    orig, log = read_log(files["orig"]), read_log(files[kind])
    assert [r.payload for r in log.events] == [r.payload for r in orig.events]
    assert log.copies == len(orig.events)
    said = f"{len(orig.events)} identical copies of events read once"
    assert said in log.loss_free and not log.missing, log.loss_free[-200:]


@pytest.mark.parametrize("kind", ["twice", "twice_renumbered"])
def test_rebuild_of_a_doubled_recording_is_the_original_policy_and_says_so(files, kind, tmp_path, capsys):
    code, out = _run(capsys, "rebuild", str(files["orig"]), "--out", str(tmp_path / "o"))
    assert code == 0, out
    code, out = _run(capsys, "rebuild", str(files[kind]), "--out", str(tmp_path / "d"))
    assert code == 0 and "identical copies of events read once" in out, out[-400:]
    want = json.loads((tmp_path / "o" / "orig.policy.json").read_text())
    got = json.loads((tmp_path / "d" / f"{kind}.policy.json").read_text())
    assert got["visits"] == want["visits"] and got["q"] == want["q"] and not got.get("partial")
    assert (tmp_path / "d" / f"{kind}.curve.csv").read_text() == (tmp_path / "o" / "orig.curve.csv").read_text()


def test_verify_and_view_of_a_doubled_recording_read_it_once(files, tmp_path, capsys):
    p = files["twice_renumbered"]
    code, out = _run(capsys, "replay", str(p), "--verify")
    assert code == 0 and out.strip().splitlines()[-1].endswith("identical copies of events read once"), out[-400:]
    code, out = _run(capsys, "view", "--recording", str(p), "--out", str(tmp_path / "v.rrd"))
    n = len(read_log(files["orig"]).events)
    assert code == 0 and f"saved {tmp_path / 'v.rrd'}: {n} events" in out, out[-400:]
    assert f"{n} identical copies of events read once" in out, out[-400:]


def _second(topic_end: str, change):
    """A rewrite's `each`: every message kept, and after each one of a channel ending `topic_end` a second one,
    its bytes changed by `change`."""
    def each(channel, message):
        if not channel.topic.endswith(topic_end):
            return [message]
        return [message, type(message)(channel_id=message.channel_id, sequence=message.sequence,
                                       log_time=message.log_time, publish_time=message.publish_time,
                                       data=change(message.data))]
    return each


def test_a_copy_spaced_otherwise_is_the_same_event_read_once(files, tmp_path):
    """The same event, encoded by another tool (its JSON spaced otherwise): a copy, as replay/forgery.py judges it;
    a skipped one (rebuild decodes only what its fold reads) too."""
    p = rewritten(tmp_path / "spaced.mcap", each=_second("/RoundEnded", lambda d: d.replace(b'"round":', b'"round": ')))
    assert read_log(p).copies == 4
    # (a skipped event's copies are looked for where its seq is checked: the game's; another source's are not, for
    # speed: they change nothing the verb makes: replay/reader.py)
    p = rewritten(tmp_path / "spaced2.mcap", each=_second("/CardRevealed", lambda d: d.replace(b'"type":', b'"type": ')))
    orig = read_log(files["orig"], only=frozenset({"SessionStarted"}))
    log = read_log(p, only=frozenset({"SessionStarted"}))
    assert log.copies > 0 and log.skipped == orig.skipped


def test_a_differing_event_of_the_same_game_seq_is_no_copy_but_a_contradiction(files, tmp_path, capsys):
    """A copy must be the same event: a game event of the same seq that differs is kept, and refused as forged."""
    p = rewritten(tmp_path / "forged.mcap", each=_second("/RoundEnded", lambda d: d.replace(b'"turns":', b'"turns":1')))
    assert read_log(p).copies == 0
    code, out = _run(capsys, "rebuild", str(p), "--out", str(tmp_path / "f"))
    assert code == 2 and "two events claim source 'game'" in out, out[-400:]



@pytest.mark.parametrize("verb", [("rebuild", "--out", "{t}/f"), ("counterfactual", "--fit-only", "--out", "{t}/cf")])
def test_a_differing_learner_event_of_the_same_seq_is_a_contradiction_too(files, tmp_path, capsys, verb):
    """A new user's trial (trial29 F2): a second QUpdated of the learner's at one seq, its value changed, rebuilt with
    exit 0 into a policy the learner never had (only `replay --verify` failed it). One process publishes as the
    learner, numbering its events: two different events at one seq are a contradiction, as the game's are."""
    def changed(data: bytes) -> bytes:
        e = json.loads(data)
        e["q_after"] += 1.0
        return json.dumps(e).encode()
    p = rewritten(tmp_path / "forged.mcap", each=_second("/QUpdated", changed))
    code, out = _run(capsys, verb[0], str(p), *(a.replace("{t}", str(tmp_path)) for a in verb[1:]))
    assert code == 2 and "two events claim source 'learner'" in out, out[-400:]

@pytest.mark.parametrize("kind", ["twice", "twice_renumbered"])
def test_recover_copies_each_event_once_and_its_copy_rebuilds_whole(files, kind, tmp_path, capsys):
    """recover copied the copies along (a "whole copy" every verb still read twice); a whole file with copies was
    "complete already", nothing written. Now its copy holds each event once, said; rebuilt, not partial."""
    out = tmp_path / "r.mcap"
    code, said = _run(capsys, "recover", str(files[kind]), "-o", str(out))
    n = len(read_log(files["orig"]).events)
    assert code == 0 and f"{n} identical copies of events not copied; {n} messages kept in {out}" in said, said[-300:]
    log = read_log(out)
    assert log.whole and log.copies == 0 and len(log.events) == n
    code, said = _run(capsys, "rebuild", str(out), "--out", str(tmp_path / "rb"))
    assert code == 0 and "PARTIAL" not in said, said[-300:]
    assert not json.loads((tmp_path / "rb" / "r.policy.json").read_text()).get("partial")


def test_a_chunk_written_twice_is_read_once(files, tmp_path, capsys):
    """A chunk's bytes written again right after it (trial28's dupchunk.mcap: rebuild exit 0, '799 events', 'no
    event lost'): its events are read once, the copies said, the policy the original's."""
    p = rewritten(tmp_path / "chunked.mcap", chunk_size=4096)
    c = scan(p).chunks[2]
    data = p.read_bytes()
    end = c.offset + c.length
    (tmp_path / "dupchunk.mcap").write_bytes(data[:end] + data[c.offset:end] + data[end:])
    log = read_log(tmp_path / "dupchunk.mcap")
    assert [r.payload for r in log.events] == [r.payload for r in read_log(files["orig"]).events]
    assert log.copies == len(c.messages) and f"{log.copies} identical copies of events read once" in log.loss_free
    code, out = _run(capsys, "rebuild", str(tmp_path / "dupchunk.mcap"), "--out", str(tmp_path / "d"))
    assert code == 0 and "identical copies of events read once" in out, out[-300:]


def test_a_file_whose_every_message_is_stored_twice_is_said_in_a_short_line(files, capsys, tmp_path):
    """A new user's trial (trial29 F3): the damage line named one "sequence goes back" clause a message: 84 KB for a
    5-round session. Past the first few, the findings are counted (replay/mcapscan.py `Scan.describe`)."""
    code, out = _run(capsys, "rebuild", str(files["twice"]), "--out", str(tmp_path / "rb"))
    [line] = [line for line in out.splitlines() if "no event lost" in line]
    assert code == 0 and len(line) < 1500 and "more findings" in line, (len(line), line[:300])
