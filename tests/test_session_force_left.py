"""`session --force` names what other verbs made of the earlier session that stays beside the new recording.

A new user's trial: `pairplay recover X` of a cut session, then `pairplay session --session X --force`: the new
X.mcap was written, and X.recovered.mcap, recover's output of the earlier session, stayed beside it unnamed, as if
it were the new session's. Now the session's run names it in one line on stderr (services/recorder.py
`earlier_outputs`), and keeps it: it is the user's. Real processes: `pairplay session` and `pairplay recover`.
"""

from __future__ import annotations

from test_study_recovered import cut_by_a_crash


def session(tmp_path, *more):
    return ["session", "--participant", "sim:ashley", "--rounds", "2", "--session", "x", "--out", str(tmp_path / "rec"),
            *more]


def test_session_force_names_the_earlier_sessions_recovered_copy_and_keeps_it(tmp_path, pairplay_cli):
    ran = pairplay_cli(*session(tmp_path))
    assert ran.returncode == 0 and "left beside" not in ran.stderr, ran
    path = tmp_path / "rec" / "x.mcap"
    cut_by_a_crash(path, "x")
    assert pairplay_cli("recover", path).returncode == 0
    copy = tmp_path / "rec" / "x.recovered.mcap"
    before = copy.read_bytes()
    ran = pairplay_cli(*session(tmp_path, "--force"))
    assert ran.returncode == 0, ran
    assert ran.stderr.splitlines() == [
        f"pairplay session: {path}: left beside it: x.recovered.mcap, recover's output of the earlier session (not this "
        "session's; kept: remove it once it is not needed)"], ran.stderr
    assert copy.read_bytes() == before  # never removed
    # without --force too, once the earlier recording is gone and its copy is not; -q keeps the line
    path.unlink()
    ran = pairplay_cli(*session(tmp_path, "-q"))
    assert ran.returncode == 0 and "x.recovered.mcap, recover's output of the earlier session" in ran.stderr, ran
