"""A recording's loss counts (`lost_count`: the bus's; `shed_count`: its recorder's own shedding) add up across every
copy of it (replay/reader.py `carry_recovery`): a restarted recorder's file that records its predecessor's losses
and its own, and a recovered file recovered again, report the totals. Before, the newest record's counts replaced
the earlier ones' (only the journal's counts and `lost_chunks` were added up). Real MCAP files throughout."""

import json

from pairplay.replay.reader import RECOVERED, read_log
from pairplay.replay.recover import recover
from pairplay.schemas import events as ev
from pairplay.services.recorder import Recorder

from test_recorder import flooding, message


def _tail_zeroed(src, dst, n=37):
    """`src` with its footer zeroed: a copy `recover` completes (no message lost)."""
    data = src.read_bytes()
    dst.write_bytes(data[:-n] + b"\0" * n)
    return dst


def test_the_loss_counts_of_every_copy_of_a_recording_add_up(tmp_path):
    first = flooding(tmp_path / "r1.mcap")
    # seq 2 lost on the bus; 3 taken; 4 shed by the full inbox; 5 taken
    assert first.inbox.put(*message(ev.RoundStarted(round=0, faces=[i // 2 for i in range(18)]), seq=3))
    assert not first.inbox.put(*message(ev.CardRevealed(round=0, turn=0, card=0, face=0, pick=0), seq=4))
    first.step(0)
    assert first.record(*message(ev.CardRevealed(round=0, turn=0, card=1, face=0, pick=1), seq=5), 5)
    assert first.close() is None
    mine = read_log(first.path).metadata[RECOVERED]
    assert (mine["lost_count"], mine["shed_count"]) == ("1", "1"), mine

    # restarted within the session: it copies the first file, records its losses, then loses seq 7 itself
    second = Recorder(None, "r1", tmp_path / "r1.mcap", restart=True)
    assert second.record(*message(ev.CardRevealed(round=0, turn=1, card=2, face=1, pick=0), seq=6), 6)
    assert second.record(*message(ev.SessionEnded(), seq=8), 8)
    assert second.close() is None
    log = read_log(second.path)
    assert [r.event.seq for r in log.events if r.event.source == "game"] == [1, 3, 5, 6, 8]
    both = log.metadata[RECOVERED]
    assert (both["lost_count"], both["shed_count"]) == ("2", "1"), both
    assert len(json.loads(both["lost"])) == 3, both["lost"]

    # recovered, then the recovered file recovered again: the same totals
    once = recover(_tail_zeroed(second.path, tmp_path / "r1.1-dmg.mcap"), tmp_path / "once.mcap").output
    twice = recover(_tail_zeroed(once, tmp_path / "once-dmg.mcap"), tmp_path / "twice.mcap").output
    for copy in (once, twice):
        counts = read_log(copy).metadata[RECOVERED]
        assert (counts["lost_count"], counts["shed_count"]) == ("2", "1"), (copy.name, counts)
