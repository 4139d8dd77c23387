"""Every number a board page sends is bounded where it enters, and a refusal is always recordable.

Trial28 F9: a pick whose `id` was 2**64+5 was taken (card 3 turned over) and became the page's last id, so
the page's next real message was "stale or repeated"; the board's MessageRejected carried that id as its
offending_seq, which every peer refused (beyond the bus's 0..2**53), and `pairplay lab` died at SIGTERM in a
traceback decoding its own outbox (services/session.py own_tail), exit 1, the recording left cut.
`pairplay lab` here is a real process and the page a real WebSocket client, as a hostile page would be.
"""

from __future__ import annotations

import json
import logging
import signal
import subprocess
import sys

import msgspec
from websockets.sync.client import connect

from pairplay.replay.reader import read_log
from pairplay.schemas import events as ev
from pairplay.schemas.envelope import SEQ_MAX, stamped
from pairplay.schemas.events import decode_event, encode_event, own_seq
from pairplay.services.bus import Bus, Outbox
from pairplay.services.guard import Refusals
from pairplay.services.runner import sent_after

HUGE = 2**64 + 5


def _reply(ws) -> dict:
    """The page's next message that is not a redraw."""
    while True:
        message = json.loads(ws.recv(timeout=60))
        if message["type"] != "state":
            return message


def test_a_page_id_beyond_the_bus_bound_is_refused_and_the_lab_still_ends_cleanly(tmp_path):
    proc = subprocess.Popen([sys.executable, "-m", "pairplay", "lab", "--participant", "human:p9", "--session",
                             "big", "--out", str(tmp_path)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        board = [proc.stdout.readline() for _ in range(2)][1].split()[1]  # http://127.0.0.1:P/s/big/board?t=T
        url = board.replace("http://", "ws://").replace("/board?", "/ws?") + "&page=board&client=hostile"
        with connect(url, open_timeout=30) as ws:
            while True:  # the game has started: a pick is about the open turn (round 0, turn 0)
                message = json.loads(ws.recv(timeout=60))
                if message["type"] == "state" and message["state"]["phase"] == "first":
                    break
            ws.send(json.dumps({"type": "pick", "id": HUGE, "round": 0, "turn": 0, "card": 3, "page_ms": 0}))
            refused = _reply(ws)
            assert refused["type"] == "rejected" and refused["reason"].startswith("malformed message"), refused
            assert "$.id" in refused["reason"], refused
            # the huge id was not taken as the page's last: a later small id is judged on what it says
            ws.send(json.dumps({"type": "pick", "id": 1, "round": 0, "turn": 0, "card": 99, "page_ms": 0}))
            refused = _reply(ws)
            assert refused["reason"].startswith("card 99 is not on the board"), refused
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 143 and "Traceback" not in err and "interrupted (SIGTERM" in err, err
    log = read_log(tmp_path / "big.mcap")
    assert not log.truncated and not log.bad, log.error
    rejected = [r.event for r in log.events if isinstance(r.event, ev.MessageRejected) and r.event.source == "board"
                and r.event.offending_source == "page:hostile"]
    assert [(r.offending_seq, r.reason.split(":")[0]) for r in rejected] == [(0, "malformed message"), (1, "card 99 is not on the board (0..17)")], rejected
    assert str(HUGE) in rejected[0].excerpt
    ended = [r.event for r in log.events if isinstance(r.event, ev.SessionEnded)]
    assert len(ended) == 1 and ended[0].reason.startswith("interrupted"), ended


def test_a_refusal_of_an_out_of_range_seq_or_unencodable_text_is_still_recorded_and_decodes():
    """Whole kind: whatever number or text a refusal is given (a page's id, a made-up seq), the MessageRejected
    it becomes is one every peer takes, and says what it was given."""
    refusals = Refusals()
    for seq in (HUGE, -1, SEQ_MAX + 1):
        [rejection] = refusals.refuse(1, "bad \ud800 thing", "pairplay/s/x/\udcff", "page:\udcfe", seq, b"\xff{}")
        payload = encode_event(stamped(rejection, session="s", source="board", seq=1, time_ns=1))
        back = decode_event(payload)
        assert back.offending_seq == 0 and str(seq) in back.reason and "\\ud800" in back.reason, back
        assert back.key == "pairplay/s/x/\\udcff" and back.offending_source == "page:\\udcfe"
    [kept] = refusals.refuse(1, "fine", "k", "src", SEQ_MAX, b"")
    assert kept.offending_seq == SEQ_MAX and kept.reason == "fine"


def test_a_process_reads_the_seq_of_its_own_payload_that_its_peers_refuse():
    """Shutdown reads its own outbox by seq (own_tail, a peer's `sent` query): one payload that does not decode
    as an event must not stop it."""
    refused = msgspec.json.encode({"type": "MessageRejected", "session": "s", "source": "board", "seq": 7,
                                   "time_ns": 1, "reason": "r", "key": "k", "offending_seq": HUGE})
    assert own_seq(refused) == 7
    assert own_seq(b"\xff not json") == -1


def test_a_sent_query_reads_a_seq_only_as_far_as_the_bus_bound():
    """A refill query's parameters come from anyone on the bus: 5000 digits raised in int() on Zenoh's thread."""
    assert sent_after("after=game:12,learner:3", "game") == 12
    assert sent_after("after=game:" + "9" * 5000, "game") == SEQ_MAX
    assert sent_after("after=game:" + "9" * 17, "game") == SEQ_MAX
    assert sent_after("after=learner:3", "game") == 0


def test_a_failed_call_on_an_outbox_is_logged_by_its_name_not_none(caplog):
    """The board's refill answer raised on its outbox's thread and the WARNING said 'could not publish None'."""
    def refill_answer():
        raise ValueError("payload its peers refuse")

    with Bus() as bus:
        outbox = Outbox(bus, "board")
        with caplog.at_level(logging.WARNING, logger="pairplay.bus"):
            outbox.call(refill_answer)
            assert outbox.flush(30)
        outbox.close(1.0)
    said = [r.getMessage() for r in caplog.records if "could not publish" in r.getMessage()]
    assert said and "publish None" not in said[0] and "(a call, refill_answer)" in said[0], said
