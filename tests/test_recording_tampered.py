"""A recording tampered with so that every MCAP check passes, read by every verb: what is wrong is said, never read
as whole (replay/reader.py rule; a hostile user's trial, trial28 F2, F3, F5). The files are made here from a
frozen sample with the mcap library's own Writer (tests/rewrite_mcap.py)."""

from __future__ import annotations

import dataclasses
import json

import pytest

from pairplay.cli.main import main
from pairplay.replay.reader import read_log
from pairplay.replay.rebuild import CURVE_READS

from rewrite_mcap import SAMPLE, rewritten

SESSION = "sample-sim-ashley"


def _run(capsys, *argv):
    code = main(list(argv))
    said = capsys.readouterr()
    return code, said.out + said.err


def _verbs(capsys, p, tmp_path):
    """(exit status, what it said) of rebuild, verify and view of `p`."""
    return {"rebuild": _run(capsys, "rebuild", str(p), "--out", str(tmp_path / "rb")),
            "verify": _run(capsys, "replay", str(p), "--verify"),
            "view": _run(capsys, "view", "--recording", str(p), "--out", str(tmp_path / "v.rrd"))}


def test_missing_game_events_are_said_by_every_verb(tmp_path, capsys):
    """F3: the RoundEnded dropped (the game's seq skips 4 numbers, every MCAP check passes): view saved a whole
    view, "0 notes"; rebuild refused it as "the session ended (completed) before round 1"."""
    p = rewritten(tmp_path / "noroundend.mcap", each=lambda c, m: [] if c.topic.endswith("/RoundEnded") else [m])
    gap = "4 events of 'game' missing: its seq jumps from 61 to 63 and in 3 other places"
    assert read_log(p).missing == gap
    said = _verbs(capsys, p, tmp_path)
    code, out = said["rebuild"]
    assert code == 2 and f"the file is damaged ({gap})" in out and "ended (completed) before" not in out, out
    code, out = said["verify"]
    assert code == 1 and "verify: FAIL" in out and gap in out and "no event lost" not in out, out
    code, out = said["view"]
    assert code == 0 and gap in out and (tmp_path / "v.partial.rrd").exists(), out


@pytest.mark.parametrize("which", ["every", "RoundEnded"])
def test_events_on_keys_naming_another_session_are_said_and_not_read(which, tmp_path, capsys):
    """F2: every topic (or the RoundEnded's) renamed to another session, payloads unchanged: rebuild exit 0,
    verify PASS, view "0 notes". As on the bus (services/guard.py), an event whose key disagrees with it is not
    taken; here it is said as the file's damage."""
    def topic(t):
        return t.replace(f"/{SESSION}/", "/s2/") if which == "every" or t.endswith("/RoundEnded") else t
    p = rewritten(tmp_path / "other.mcap", topic=topic)
    words = "not what their key names (pairplay/s2/"
    log = read_log(p)
    assert words in log.damaged and f"it names session 's2', its payload '{SESSION}'" in log.damaged, log.damaged
    said = _verbs(capsys, p, tmp_path)
    for verb, (code, out) in said.items():
        assert code != 0 or verb == "view", (verb, out)
        assert words in out and "PASS" not in out, (verb, out)


@pytest.mark.parametrize("schema, why", [(b'{"type":"string"}', "not the JSON Schema of its event"),
                                         (b"\xff\xfe not json", "not JSON")])
def test_schemas_that_are_not_pairplays_are_said_by_every_verb(schema, why, tmp_path, capsys):
    """F5: every schema replaced (by another JSON Schema, by bytes that are not JSON): the events still decode (the
    JSON is read, not the schema), but the file misdescribes them to other MCAP readers; every verb passed it with
    no word. Now said, nothing lost: rebuild and view whole, verify PASS, each with the line."""
    p = rewritten(tmp_path / "schemas.mcap", schema=lambda data: schema)
    words = f"channels' schemas are not pairplay's (ServiceStarted: {why}, ...)"
    log = read_log(p)
    assert words in log.loss_free and not log.missing, log.loss_free
    said = _verbs(capsys, p, tmp_path)
    for verb, (code, out) in said.items():
        assert code == 0 and words in out, (verb, out)
    assert said["verify"][1].strip().splitlines()[-1].startswith("verify: PASS; ")
    assert (tmp_path / "v.rrd").exists() and not json.loads((tmp_path / "rb" / "schemas.policy.json").read_text())["partial"]


def _seq_changed(source: str, seq: int, new: int | None):
    """`rewritten`'s `each`: the event of `source` at `seq` given the seq `new` (None: dropped), every other kept."""
    def each(channel, message):
        if f"/{source}/" not in channel.topic:
            return [message]
        event = json.loads(message.data)
        if event["seq"] != seq:
            return [message]
        if new is None:
            return []
        event["seq"] = new
        return [dataclasses.replace(message, data=json.dumps(event, separators=(",", ":")).encode())]
    return each


def _every_verb(capsys, p, tmp_path):
    """`_verbs` and rebuild --partial, counterfactual --fit-only and recover of `p`."""
    said = _verbs(capsys, p, tmp_path)
    said["rebuild --partial"] = _run(capsys, "rebuild", str(p), "--out", str(tmp_path / "rp"), "--partial")
    said["counterfactual"] = _run(capsys, "counterfactual", str(p), "--fit-only", "--out", str(tmp_path / "cf"))
    said["recover"] = _run(capsys, "recover", str(p), "-o", str(tmp_path / "r.mcap"))
    return said


def _partial(tmp_path, folder: str, p) -> str:
    return json.loads((tmp_path / folder / f"{p.stem}.policy.json").read_text())["partial"]


@pytest.mark.parametrize("source, seq, new, gap", [
    ("learner", 16, 999, "'learner': 1 event missing: its seq jumps from 15 to 17, an event has seq 999, far past "
                         "its others (the last 141)"),
    ("game", 61, None, "1 event of 'game' missing: its seq jumps from 60 to 62")])
def test_a_hole_in_the_seq_of_a_source_the_policy_is_made_of_is_said_and_flags_the_policy(source, seq, new, gap,
                                                                                           tmp_path, capsys):
    """trial29 F10: the learner's seq 16 rewritten as 999 (every MCAP check passes): rebuild wrote a whole policy and
    view "0 notes", exit 0, no word; only verify failed, DIFFERS lines not naming the hole (the reader checked the
    game's seq alone). And a hole in the game's seq was refused by rebuild, but written with --partial unflagged.
    Now every verb says the hole, in the reader's words; rebuild refuses it without --partial and flags the policy
    with it; recover says no copy gives the events back."""
    p = rewritten(tmp_path / "hole.mcap", each=_seq_changed(source, seq, new))
    assert read_log(p).missing == gap
    assert read_log(p, only=CURVE_READS).missing == gap  # (rebuild's read: the learner's events by tag and seq)
    said = _every_verb(capsys, p, tmp_path)
    code, out = said["rebuild"]
    assert code == 2 and f"the file is damaged ({gap})" in out and "--partial" in out, out
    code, out = said["rebuild --partial"]
    assert code == 0 and f"PARTIAL session: {gap}" in out and _partial(tmp_path, "rp", p) == gap, out
    code, out = said["verify"]
    assert code == 1 and f"verify: FAIL: the file is damaged ({gap})" in out, out
    code, out = said["view"]
    assert code == 0 and gap in out and (tmp_path / "v.partial.rrd").exists(), out
    code, out = said["counterfactual"]
    assert code == 0 and f"not whole ({gap})" in out, out
    code, out = said["recover"]
    assert code == 0 and f"{gap}: no recover gives them back" in out, out


def test_a_hole_in_the_participants_seq_is_said_and_leaves_the_policy_whole(tmp_path, capsys):
    """trial29 F10, another source: the participant's seq 10 dropped. The policy is made of the game's and the
    learner's events alone: rebuild writes it whole, exit 0, and says the hole; the verbs that read the
    participant's events (verify, view, counterfactual) say the file lacks one."""
    p = rewritten(tmp_path / "phole.mcap", each=_seq_changed("participant", 10, None))
    gap = "1 event of 'participant' missing: its seq jumps from 9 to 11"
    said = _every_verb(capsys, p, tmp_path)
    code, out = said["rebuild"]
    assert code == 0 and f"{gap} (the policy does not depend on them)" in out and not _partial(tmp_path, "rb", p), out
    for verb in ("verify", "view", "counterfactual", "recover"):
        assert gap in said[verb][1], (verb, said[verb])
    assert said["verify"][0] == 1


def test_channels_repeated_in_every_chunk_leave_no_hole(tmp_path):
    """A writer may repeat each channel's record in every chunk (MCAP lets it): the reader kept the seqs read on a
    channel per record, so each repeat dropped the seqs read before it and the other channels' seqs of the same
    source around them read as holes. A file of every event, its channels repeated, has none; a dropped event
    is still found."""
    p = rewritten(tmp_path / "repeated.mcap", chunk_size=4096, repeat_channels=True)
    for only in (None, CURVE_READS):
        log = read_log(p, only=only)
        assert log.whole and not log.seq_jumps and not log.missing, log.missing
    p = rewritten(tmp_path / "hole.mcap", chunk_size=4096, repeat_channels=True,
                  each=_seq_changed("learner", 100, None))
    assert read_log(p, only=CURVE_READS).missing == "1 event of 'learner' missing: its seq jumps from 99 to 101"


def _dropped(source: str, seqs):
    """`rewritten`'s `each`: the events of `source` whose seq is in `seqs` dropped, every other kept."""
    def each(channel, message):
        return [] if f"/{source}/" in channel.topic and json.loads(message.data)["seq"] in seqs else [message]
    return each


def _refused_and_flagged(capsys, p, tmp_path, gap):
    """rebuild of `p` refused without --partial and flagged with it, in the reader's words `gap`."""
    assert read_log(p).missing == gap
    assert read_log(p, only=CURVE_READS).missing == gap  # (rebuild's read: the learner's events by tag and seq)
    code, out = _run(capsys, "rebuild", str(p), "--out", str(tmp_path / "rb"))
    assert code == 2 and f"the file is damaged ({gap})" in out and "--partial" in out, out
    code, out = _run(capsys, "rebuild", str(p), "--out", str(tmp_path / "rp"), "--partial")
    assert code == 0 and _partial(tmp_path, "rp", p) == gap, out


@pytest.mark.parametrize("source, seqs, gap", [
    ("learner", range(1, 13), "'learner': its first 12 events missing: its seq starts at 13"),
    ("game", {1}, "'game': its first event missing: its seq starts at 2")])
def test_a_hole_at_the_start_of_a_seq_is_said_and_refused(source, seqs, gap, tmp_path, capsys):
    """trial32 E: the learner's seqs 1..12 (its ServiceStarted and first Q update) or the game's seq 1 dropped:
    rebuild wrote a whole policy, exit 0, no word (events before a source's first one in the file were not
    counted). Every source's seq starts at 1 in a recording of its session: a first seq past 1 is a hole."""
    _refused_and_flagged(capsys, rewritten(tmp_path / "head.mcap", each=_dropped(source, seqs)), tmp_path, gap)


@pytest.mark.parametrize("last_q, gap", [
    (True, "10 SuggestionMade of 'learner' missing (55 for the 65 SuggestionRequested of 'game')"),
    (False, "1 RewardGiven of 'learner' missing (64 for the 65 SuggestionMade of 'learner')")])
def test_the_learners_last_events_dropped_are_said_and_refused(last_q, gap, tmp_path, capsys):
    """trial32 E: the learner's events from its last Q update on dropped (no seq after them shows a hole):
    rebuild wrote a whole, wrong policy, exit 0, no word. The requests the learner answered fewer of say it, and
    so do its suggestions when only its last event (the RewardGiven settling the last one) is dropped."""
    learner = [r.event for r in read_log(SAMPLE).events if r.event.source == "learner"]
    start = (max(e.seq for e in learner if type(e).__name__ == "QUpdated") if last_q
             else max(e.seq for e in learner))
    p = rewritten(tmp_path / "tail.mcap", each=_dropped("learner", range(start, 10**6)))
    _refused_and_flagged(capsys, p, tmp_path, gap)


def _ended_by_a_signal(each):
    """`each`, and the game's SessionEnded made an end by SIGINT (as the game writes it on one)."""
    def changed(channel, message):
        if channel.topic.endswith("/SessionEnded"):
            event = json.loads(message.data)
            event.update(reason="interrupted", detail="SIGINT")
            message = dataclasses.replace(message, data=json.dumps(event, separators=(",", ":")).encode())
        return each(channel, message)
    return changed


def test_a_request_unanswered_at_a_signals_end_is_no_loss_but_two_are(tmp_path, capsys):
    """A session ended by a signal may stop between the game's last request and the learner's answer: that one
    unanswered request is its end, not a loss; two are the learner's last events missing."""
    made = sorted(r.event.seq for r in read_log(SAMPLE).events if type(r.event).__name__ == "SuggestionMade")
    one = rewritten(tmp_path / "one.mcap", each=_ended_by_a_signal(_dropped("learner", range(made[-1], 10**6))))
    assert not read_log(one).missing and not read_log(one, only=CURVE_READS).missing
    two = rewritten(tmp_path / "two.mcap", each=_ended_by_a_signal(_dropped("learner", range(made[-2], 10**6))))
    assert "2 SuggestionMade of 'learner' missing (" in read_log(two).missing, read_log(two).missing


@pytest.mark.parametrize("seq, new, gap", [
    (21, 20, "'participant': seq 20 held by two events, none by 21: one renumbered"),
    (30, 999, "an event has seq 999, far past its others (the last 261)")])
def test_a_repeated_seq_and_a_seq_far_past_are_said_as_such(seq, new, gap, tmp_path, capsys):
    """trial32 E: a seq rewritten 21 -> 20 (two events seq 20, none 21) was said "1 event ... missing: jumps from
    20 to 22", one rewritten far past the others as hundreds of events missing: each is said as what it is."""
    p = rewritten(tmp_path / "renumbered.mcap", each=_seq_changed("participant", seq, new))
    for only in (None, CURVE_READS):
        assert gap in read_log(p, only=only).missing, read_log(p, only=only).missing


def test_a_q_update_dropped_and_the_seqs_after_it_renumbered_is_said(tmp_path, capsys):
    """The learner's last QUpdated dropped and its later events renumbered down one (no hole in its seq, every
    request answered, every suggestion settled): its RewardGiven that learned outnumber its Q updates."""
    last_q = max(r.event.seq for r in read_log(SAMPLE).events if type(r.event).__name__ == "QUpdated")

    def each(channel, message):
        event = json.loads(message.data)
        if "/learner/" not in channel.topic or event["seq"] < last_q:
            return [message]
        if event["seq"] == last_q:
            return []
        event["seq"] -= 1
        return [dataclasses.replace(message, data=json.dumps(event, separators=(",", ":")).encode())]
    p = rewritten(tmp_path / "renumbered.mcap", each=each)
    gap = "1 QUpdated of 'learner' missing (9 for the 10 RewardGiven that learned)"  # (not "the last": trial33 G)
    _refused_and_flagged(capsys, p, tmp_path, gap)


def _cut_and_renumbered(source: str, seq: int):
    """`rewritten`'s `each`: the event of `source` at `seq` dropped and its later seqs one less (no hole in its seq)."""
    def each(channel, message):
        event = json.loads(message.data)
        if f"/{source}/" not in channel.topic or event["seq"] < seq:
            return [message]
        if event["seq"] == seq:
            return []
        event["seq"] -= 1
        return [dataclasses.replace(message, data=json.dumps(event, separators=(",", ":")).encode())]
    return each


_PICKS = "CardRevealed and 1 PickRejected of 'game' answer"


@pytest.mark.parametrize("seqs, gap", [
    (range(1, 6), "'participant': its first 5 events missing: its seq starts at 6"),
    (range(259, 10**6), f"1 CardPicked of 'participant' missing (the 130 {_PICKS} 130)"),
    (range(0, 10**6), f"130 CardPicked of 'participant' missing (the 130 {_PICKS} 1)")])
def test_the_participants_first_last_or_every_event_dropped_is_said_by_every_verb(seqs, gap, tmp_path, capsys):
    """trial33 E: the participant's seqs 1..5, its last pick (and what it perceived before it), or every event of it
    dropped: rebuild exit 0 silent, recover "complete already", view not .partial, verify "verified the whole
    session" (its seq was checked between its events only, not at its start or end). Its seq starts at 1 (as the
    game's and the learner's); the game answers every pick with a CardRevealed or PickRejected: more of them than
    picks are the picker's events missing. The policy
    does not depend on them (rebuild writes it whole, saying so), every other verb says them."""
    p = rewritten(tmp_path / "p.mcap", each=_dropped("participant", seqs))
    assert read_log(p).missing == gap and read_log(p, only=CURVE_READS).missing == gap
    said = _verbs(capsys, p, tmp_path)
    code, out = said["rebuild"]
    assert code == 0 and f"{gap} (the policy does not depend on them)" in out, out
    assert _partial(tmp_path, "rb", p) == "", out
    code, out = said["verify"]
    assert code == 1 and gap in out and "verified the whole session" not in out, out
    code, out = said["view"]
    assert code == 0 and gap in out and (tmp_path / "v.partial.rrd").exists(), out
    code, out = _run(capsys, "recover", str(p), "--out", str(tmp_path / "r.mcap"))
    assert f"{gap}: no recover gives them back" in out, out
    code, out = _run(capsys, "counterfactual", str(p), "--fit-only", "--out", str(tmp_path / "cf"))
    assert "not whole" in out and gap in out, out


@pytest.mark.parametrize("tag, gap", [
    ("SuggestionRequested", "1 SuggestionRequested of 'game' missing (the 65 SuggestionMade of 'learner' answer 64)"),
    ("CardRevealed", "1 CardRevealed or PickRejected of 'game' missing (129 CardRevealed and 1 PickRejected for the "
                     "131 CardPicked of 'participant' or 'board')"),
    # an event of another kind, which nothing answers one for one: the seqs the learner's answers name move off the
    # game's requests (before: rebuild, recover, counterfactual silent, counterfactual fitted fewer picks: trial33 G)
    ("TurnResolved", "'game': its seqs renumbered (an event cut or added): the request_seq of 34 SuggestionMade of "
                     "'learner' name no SuggestionRequested (the first: 135)"),
    # the last turn's, after the last request (no request_seq moves): the learner's reward settles it
    ("last TurnResolved", "1 TurnResolved of 'game' missing (a RewardGiven of 'learner' settles round 4 turn 16, "
                          "which no TurnResolved resolves)")])
def test_a_game_event_cut_and_the_rest_renumbered_is_said_and_refused(tag, gap, tmp_path, capsys):
    """trial33 G: a game's request or reveal cut from the middle and its later seqs renumbered (no hole in its seq):
    rebuild exit 0 silent, counterfactual fitted fewer picks silently. The learner answers each request once (its
    answers to no request say the game's event missing), the game each pick (picks it answered none of say it)."""
    seqs = sorted(r.event.seq for r in read_log(SAMPLE).events
                  if r.event.source == "game" and type(r.event).__name__ == tag.split()[-1])
    p = rewritten(tmp_path / "g.mcap", each=_cut_and_renumbered("game", seqs[-1 if tag.startswith("last")
                                                                             else min(30, len(seqs) // 2)]))
    _refused_and_flagged(capsys, p, tmp_path, gap)
    code, out = _run(capsys, "counterfactual", str(p), "--fit-only", "--out", str(tmp_path / "cf"))
    assert f"not whole ({gap})" in out, out
    code, out = _run(capsys, "recover", str(p), "-o", str(tmp_path / "r.mcap"))
    assert code == 0 and f"{gap}: no recover gives them back" in out, out


def test_a_rounds_deal_cut_leaves_its_turns_out_of_a_fit(tmp_path, capsys):
    """A game's RoundStarted cut (and its later seqs renumbered): counterfactual fitted the round's turns under the
    round before's deal, turns impossible under it: the likelihood was NaN, a traceback (ValueError: zero-size array)
    once the fit's interval was empty. A turn is fitted under its own round's deal only."""
    seqs = sorted(r.event.seq for r in read_log(SAMPLE).events
                  if r.event.source == "game" and type(r.event).__name__ == "RoundStarted")
    p = rewritten(tmp_path / "g.mcap", each=_cut_and_renumbered("game", seqs[2]))
    code, out = _run(capsys, "counterfactual", str(p), "--fit-only", "--out", str(tmp_path / "cf"))
    assert code == 0 and "turn left out of the fit: round 3 (20 turns): no RoundStarted before it" in out, out
    assert "not whole ('game': its seqs renumbered" in out and "Traceback" not in out, out


def test_a_participant_event_cut_and_the_rest_renumbered_is_said(tmp_path, capsys):
    """trial33 G, the participant's kind: what it perceived of a suggestion cut from the middle and its later seqs
    renumbered (no hole, as many picks as the game answered): no verb said it. The game's answers name the picks
    by seq (pick_seq): they move off the participant's CardPicked. The policy does not depend on it."""
    seq = sorted(r.event.seq for r in read_log(SAMPLE).events
                 if r.event.source == "participant" and type(r.event).__name__ == "SuggestionPerceived")[30]
    p = rewritten(tmp_path / "p.mcap", each=_cut_and_renumbered("participant", seq))
    gap = ("'participant': its seqs renumbered (an event cut or added): the pick_seq of 35 CardRevealed or "
           "PickRejected of 'game' name no CardPicked (the first: 126)")
    assert read_log(p).missing == gap and read_log(p, only=CURVE_READS).missing == gap, read_log(p).missing
    code, out = _run(capsys, "rebuild", str(p), "--out", str(tmp_path / "rb"))
    assert code == 0 and f"{gap} (the policy does not depend on them)" in out, out
    code, out = _run(capsys, "counterfactual", str(p), "--fit-only", "--out", str(tmp_path / "cf"))
    assert f"not whole ({gap})" in out, out


def test_a_seq_0_is_said_as_such_not_as_a_first_event_missing(tmp_path):
    """trial33 G: a learner's seq 1 rewritten as 0 was said "its first event missing: its seq starts at 2"."""
    p = rewritten(tmp_path / "zero.mcap", each=_seq_changed("learner", 1, 0))
    assert read_log(p).missing == "'learner': an event has seq 0 (seqs start at 1; its next is 2)", read_log(p).missing


def test_a_verify_that_fails_does_not_say_it_verified_the_whole_session(tmp_path, capsys):
    """trial33 E: verify's FAIL came after "verified the whole session (N rounds)": a FAIL verified nothing.
    (A Q update's value changed: every seq whole, the learner's recomputed update differs.)"""
    def each(channel, message):
        event = json.loads(message.data)
        if not channel.topic.endswith("/QUpdated") or event["seq"] != 4:
            return [message]
        event["q_after"] = 7.0
        return [dataclasses.replace(message, data=json.dumps(event, separators=(",", ":")).encode())]
    p = rewritten(tmp_path / "q.mcap", each=each)
    code, out = _run(capsys, "replay", str(p), "--verify")
    assert code == 1 and "DIFFERS" in out and "verify: FAIL" in out, out
    assert "verified the whole session" not in out and "compared the whole session (4 rounds)" in out, out


@pytest.fixture(scope="module")
def robot_session(tmp_path_factory):
    """A real one-round session with the virtual robot (its bridge publishes as 'robot')."""
    from pairplay.schemas.events import SessionConfig
    from pairplay.services.robot.choice import RobotChoice
    from pairplay.services.session import run_session

    config = SessionConfig(session="robot-head", participant="sim:ashley", persona="ashley", seed=0, rounds=1)
    whole = run_session(config, tmp_path_factory.mktemp("robot") / "whole.mcap",
                        robot=RobotChoice("virtual?time_scale=0"))
    assert not read_log(whole).missing and any(r.event.source == "robot" for r in read_log(whole).events)
    return whole


@pytest.mark.parametrize("which", ["first", "last"])
def test_the_robots_first_or_last_event_dropped_is_said(which, robot_session, tmp_path, capsys):
    """trial33 E: a robot's seq 1 (its ServiceStarted) or its last RobotActed dropped: every verb silent, verify
    PASS. The robot's bridge is one process from the session's start (asked for its first events if it started
    before the recorder): its seq starts at 1; it reports every suggestion it had (a RobotActed each, or the
    recorder counts the ones it never had). The policy does not depend on it."""
    robot = [r.event for r in read_log(robot_session).events if r.event.source == "robot"]
    made = sum(type(r.event).__name__ == "SuggestionMade" for r in read_log(robot_session).events)
    seqs = {1} if which == "first" else {max(e.seq for e in robot if type(e).__name__ == "RobotActed")}
    gap = ("'robot': its first event missing: its seq starts at 2" if which == "first" else
           f"1 RobotActed of 'robot' missing ({made - 1} for the {made} SuggestionMade of 'learner')")
    p = rewritten(tmp_path / "r.mcap", src=robot_session, each=_dropped("robot", seqs))
    assert read_log(p).missing == gap and read_log(p, only=CURVE_READS).missing == gap
    code, out = _run(capsys, "rebuild", str(p), "--out", str(tmp_path / "rb"))
    assert code == 0 and f"{gap} (the policy does not depend on them)" in out, out
    code, out = _run(capsys, "replay", str(p), "--verify")
    assert code == 1 and gap in out, out


def test_a_robot_that_sent_nothing_in_a_session_started_with_one_is_said(robot_session, tmp_path, capsys):
    """trial33 E's robot, all of it: every event of the robot dropped from a session started with one was said by no
    verb (the RobotActed were counted only when the robot sent some). The session's SessionStarted names the robot
    it was started with (by kind: no host, no key); one named, none of its events read, is said by every verb."""
    [start] = read_log(robot_session).of("SessionStarted")
    assert start.config.robot == "virtual"
    [start] = read_log(SAMPLE).of("SessionStarted")  # a session without one (and every older recording): nothing
    assert start.config.robot == "" and not read_log(SAMPLE).missing
    made = sum(type(r.event).__name__ == "SuggestionMade" for r in read_log(robot_session).events)
    gap = (f"the robot sent nothing: no event of 'robot' in a session started with robot 'virtual', for the {made} "
           "SuggestionMade of 'learner'")
    p = rewritten(tmp_path / "r.mcap", src=robot_session, each=_dropped("robot", range(0, 10**6)))
    assert read_log(p).missing == gap and read_log(p, only=CURVE_READS).missing == gap, read_log(p).missing
    code, out = _run(capsys, "rebuild", str(p), "--out", str(tmp_path / "rb"))
    assert code == 0 and f"{gap} (the policy does not depend on them)" in out, out
    code, out = _run(capsys, "replay", str(p), "--verify")
    assert code == 1 and gap in out and "verify: FAIL" in out, out
