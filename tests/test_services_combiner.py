"""The combiner answers a CombineRequested on the bus with the merge of
algorithm 4 over policies rebuilt from recordings, and a bad request with a
reason, without stopping."""

import queue

from pairplay.core.combine import combine
from pairplay.core.policies import users_from_policies
from pairplay.replay.rebuild import rebuild_recording
from pairplay.schemas import events as ev
from pairplay.schemas.envelope import stamped
from pairplay.schemas.events import decode_event, encode_event
from pairplay.schemas.keys import event_key
from pairplay.schemas.policy import read_policy
from pairplay.schemas.session import SessionConfig
from pairplay.services.combiner import CombinerLogic
from pairplay.services.runner import Node
from pairplay.services.session import run_session

from busutil import collect, connector, listener, wait_until


def test_combine_requests_over_the_bus(tmp_path):
    recs = []
    for who in ("ashley", "vincent"):
        for seed in (1, 2):  # two games each: a profile (algorithm 3) compares a user's policies
            cfg = SessionConfig(session=f"c-{who}-{seed}", participant=f"sim:{who}", persona=who, seed=seed, rounds=6)
            recs.append(str(run_session(cfg, tmp_path / f"{cfg.session}.mcap")))
    with listener() as server, connector(server) as client:
        node = Node(server, CombinerLogic(tmp_path), "lab", resume=False)
        node.start()
        answers = collect(client, "pairplay/lab/combiner/PolicyCombined")
        key = event_key("lab", "console", "CombineRequested")
        assert wait_until(lambda: client.matching(key))
        requests = [ev.CombineRequested(request_id="r1", recordings=recs, output_path=str(tmp_path / "bias.json")),
                    ev.CombineRequested(request_id="r2", policies=[str(tmp_path / "missing.json")]),
                    ev.CombineRequested(request_id="r3", recordings=recs, output_path="/etc/evil.json")]
        for seq, r in enumerate(requests, 1):
            client.put(key, encode_event(stamped(r, session="lab", source="console", seq=seq, time_ns=seq)))
        client.put(key, b"garbage")
        got = []
        while len(got) < 3:
            node.step(0.5)
            try:
                got.append(decode_event(answers.get(timeout=0.01)[1]))
            except queue.Empty:
                pass
        assert wait_until(lambda: node.step(0.05) or node.driver.rejections == 1, 10)
    ok, bad, outside = sorted(got, key=lambda e: e.request_id)
    assert not outside.ok and "outside the combiner's directory" in outside.error
    users, _ = users_from_policies([rebuild_recording(rec).policy for rec in recs], 0)
    expected = combine(users)
    assert ok.ok and ok.actions == [int(a) for a in expected.policy] and ok.decided_by == expected.rules
    assert ok.users == ["ashley", "vincent"]
    assert read_policy(tmp_path / "bias.json").greedy == ok.actions
    assert not bad.ok and "missing.json" in bad.error
    assert node.driver.rejections == 1  # the garbage, with a reason; the combiner went on


def test_a_recording_with_no_whole_round_is_refused_with_its_reason_and_nothing_written(tmp_path):
    """Combining a recording cut before its first round ended folded a policy of 0 rounds into the
    merge (replay/check.py `no_whole_round`); the answer now says why and nothing is written."""
    from pathlib import Path

    from pairplay.replay.reader import read_log
    from pairplay.replay.writer import EventLogWriter

    sample = Path(__file__).resolve().parents[1] / "recordings" / "samples" / "sim-ashley.mcap"
    w = EventLogWriter(tmp_path / "cut.mcap")
    for r in read_log(sample).events:
        if type(r.event).__name__ == "RoundEnded":
            break
        w.write(r.key, r.payload, log_time_ns=r.event.time_ns, sequence=r.event.seq)
    w.close()
    logic = CombinerLogic(tmp_path)
    [answer] = logic.handle(ev.CombineRequested(request_id="r", recordings=["cut.mcap", str(sample)],
                                                output_path="m.json"))
    assert not answer.ok and "holds no whole round: the recording stops before round 1 of " in answer.error
    assert "cut.mcap" in answer.error and not (tmp_path / "m.json").exists()


def test_a_user_of_one_policy_is_refused_as_pairplay_combine_refuses_it(tmp_path):
    """A participant with one policy has no profile (algorithm 3 compares two or more): `pairplay combine` refused
    it, while the combiner service merged it as a participant who perceives every channel."""
    recs = []
    for who in ("ashley", "vincent"):
        cfg = SessionConfig(session=f"one-{who}", participant=f"sim:{who}", persona=who, seed=1, rounds=3)
        recs.append(run_session(cfg, tmp_path / f"{cfg.session}.mcap").name)
    [answer] = CombinerLogic(tmp_path).handle(ev.CombineRequested(request_id="r", recordings=recs,
                                                                  output_path="m.json"))
    assert not answer.ok and "two or more policies of a participant" in answer.error
    assert not (tmp_path / "m.json").exists()


def test_a_named_pipe_named_by_a_request_is_refused_and_the_next_request_answered(tmp_path):
    """A CombineRequested naming a FIFO in the combiner's directory blocked `pairplay run combiner` for good, every
    later request unanswered (a hostile user's trial, trial28 F12): the input check (pairplay/inputs.py) refuses it."""
    import os
    import threading

    os.mkfifo(tmp_path / "fifo.json")
    answers = []
    worker = threading.Thread(target=lambda: answers.extend(CombinerLogic(tmp_path).handle(
        ev.CombineRequested(request_id="r", policies=["fifo.json"], recordings=[], output_path="m.json"))),
        daemon=True)
    worker.start()
    worker.join(30)
    if worker.is_alive():  # unblock the reader so the test process can end
        os.close(os.open(tmp_path / "fifo.json", os.O_WRONLY | os.O_NONBLOCK))
    assert answers and not answers[0].ok and "named pipe" in answers[0].error, answers
