"""The tests' command zygote (tests/cli_zygote.py) runs every command it is sent, however many arrive at once.

Requests sent together from several threads reached the zygote in one read of its stdin: it took the
first line and left the rest in sys.stdin's buffer, which select() never reported again, so those
commands waited for the next request (the last ones for ever: a 60 s timeout on the pid). The tests
that start their commands side by side (test_study_guard's refusals beside a server) met it at once.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor, wait


def test_commands_sent_at_once_all_run(pairplay_cli):
    with ThreadPoolExecutor(12) as pool:
        futures = [pool.submit(pairplay_cli, "--version", timeout=30) for _ in range(12)]
        done, late = wait(futures, timeout=30)
        assert not late, f"{len(late)} of 12 commands sent at once never ran"
    for future in done:
        ran = future.result()
        assert ran.returncode == 0 and ran.stdout.startswith("pairplay "), (ran.returncode, ran.stderr)
