"""`replay --verify` names what it recomputed beyond the recording (trial33 L: "game 910 derived events
compared: DIFFERS (2 recomputed beyond the recording)", then "verify: FAIL", and not one line of what,
even with -v): the first SHOWN of them, then how many more."""

from __future__ import annotations

from mcap.reader import make_reader
from rewrite_mcap import SAMPLE, rewritten


def test_verify_lists_the_events_recomputed_beyond_the_recording(tmp_path, pairplay_cli):
    with open(SAMPLE, "rb") as f:  # the learner's last reward (filed after the session's end) left out
        last = max(m.sequence for _, c, m in make_reader(f).iter_messages() if c.topic.endswith("/RewardGiven"))
    path = rewritten(tmp_path / "notail.mcap",
                     each=lambda c, m: [] if c.topic.endswith("/RewardGiven") and m.sequence == last else [m])
    done = pairplay_cli("replay", path, "--verify")
    assert done.returncode == 1 and done.stdout.splitlines()[-1].startswith("verify: FAIL")
    assert "DIFFERS (1 recomputed beyond the recording)" in done.stdout
    # counted from 1, as the verdict's "rounds 1-N of M recorded whole" (trial34 C: the event's 0-based fields)
    assert "    recomputed, not in the recording: RewardGiven seq 141 (round 4, turn 16)\n" in done.stdout
