"""The verbs as a researcher types them: session, rebuild, replay --verify,
recover; and a learner started alone with `pairplay run` joining a session."""

import subprocess
from pathlib import Path

import pytest

from pairplay.schemas.policy import read_policy

from cli_zygote import shared


@pytest.fixture
def pairplay(pairplay_cli):
    """`python -m pairplay ARGS` as a researcher types it (each its own process; conftest's pairplay_cli)."""
    return pairplay_cli


def test_session_then_rebuild_then_verify_then_recover(tmp_path, pairplay):
    r = pairplay("session", "--participant", "sim:frances", "--seed", "4", "--rounds", "5", "--session", "cli1",
                 "--out", str(tmp_path))
    assert r.returncode == 0, r.stdout + r.stderr
    rec = tmp_path / "cli1.mcap"
    assert rec.exists() and "rounds played: 5; picks per round (18 = perfect): [" in r.stdout
    picks = [int(x) for x in r.stdout.split("picks per round (18 = perfect): [")[1].split("]")[0].split(",")]
    assert len(picks) == 5 and all(n >= 18 and n % 2 == 0 for n in picks)  # picks, not turns
    r = pairplay("rebuild", str(rec), "--out", str(tmp_path / "rebuilt"))
    assert r.returncode == 0, r.stdout + r.stderr
    policy = read_policy(tmp_path / "rebuilt" / "cli1.policy.json")
    assert policy.participant == "frances" and policy.seed == 4
    assert (tmp_path / "rebuilt" / "learning-curves.png").stat().st_size > 0
    r = pairplay("replay", str(rec), "--verify")
    assert r.returncode == 0 and "verify: PASS" in r.stdout, r.stdout
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(rec.read_bytes()[:-20])  # the footer lost: every message is there, the file is not whole
    r = pairplay("recover", str(cut))
    assert r.returncode == 0 and "cut short" in r.stdout, r.stdout
    r = pairplay("replay", str(tmp_path / "cut.recovered.mcap"), "--verify")
    assert "verify: PASS" in r.stdout, r.stdout  # recovered whole
    r = pairplay("replay", str(rec), "--speed", "max")
    assert r.returncode == 0 and "replayed" in r.stdout
    first = r.stdout.splitlines()[0]  # where a view attaches: pairplay view --session cli1 --connect ENDPOINT
    assert first.startswith("replaying session cli1; bus listening on tcp/127.0.0.1:"), first


def test_bad_command_lines_get_a_clear_error(tmp_path, pairplay):
    r = pairplay("session", "--participant", "sim:nobody", "--out", str(tmp_path))
    assert r.returncode == 2 and "unknown persona" in r.stderr and r.stdout == ""  # one line, on stderr
    r = pairplay("session", "--participant", "robot:x", "--out", str(tmp_path))
    assert r.returncode == 2 and "sim:<persona> or human:<id>" in r.stderr
    r = pairplay("rebuild", str(tmp_path / "missing.mcap"), "--out", str(tmp_path))
    assert r.returncode == 2 and "no such recording" in r.stderr
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"junk")
    r = pairplay("rebuild", str(junk), "--out", str(tmp_path))
    assert r.returncode == 2 and "not an MCAP file" in r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["junk.mcap"]  # nothing written


def test_services_run_alone_in_their_own_processes_join_a_session(tmp_path, pairplay):
    """The session's process is the router; a learner and a participant, each in
    its own process, connect to it as clients and reach each other through it."""
    # each its own process, forked from this test process's zygote (tests/cli_zygote.py): how they meet on the
    # bus is tested here, not how a process starts (each `python -m pairplay` paid ~0.9 s of CPU importing)
    session = shared().start(["session", "--participant", "sim:blind", "--seed", "2", "--rounds", "3", "--session",
                              "cli2", "--out", str(tmp_path), "--external", "learner", "--external", "participant"],
                             stderr=subprocess.DEVNULL)
    procs = []
    try:
        endpoint = session.stdout.readline().split("listening on ")[1].split()[0]
        procs = [shared().start(["run", service, "--session", "cli2", "--connect", endpoint],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                 for service in ("learner", "participant")]
        assert [p.wait(60) for p in procs] == [0, 0]
        assert session.wait(60) == 0
    finally:
        for p in procs + [session]:
            if p.poll() is None:
                p.kill()
                p.wait()
    r = pairplay("replay", str(Path(tmp_path) / "cli2.mcap"), "--verify")
    assert "verify: PASS" in r.stdout, r.stdout
