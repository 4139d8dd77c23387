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


def test_a_read_only_command_sees_its_folder_read_only_and_no_other_process_does(tmp_path):
    """`run(..., read_only=...)`: the command alone runs in a mount namespace of its own where the folder is
    read-only (an empty tmpfs, or the folder bound read-only, its files kept): test_cli_mistakes' read-only
    rows, which each paid a `python -m pairplay` under `unshare --mount` before. The next command, and this
    process, see the folder as it is: writable."""
    import os

    import pytest

    from cli_zygote import Zygote
    if os.geteuid() != 0:
        pytest.skip("needs root for a mount namespace")
    (tmp_path / "ro").mkdir()
    (tmp_path / "kept").mkdir()
    (tmp_path / "kept" / "study.toml").write_text("the user's file")
    init = ["protocol", "init", "--study", "thesis-ch7", "--quiet"]
    with Zygote(scratch=tmp_path) as zygote:
        for how, place in (("tmpfs", tmp_path / "ro"), ("bind", tmp_path / "kept")):
            refused = zygote.run([*init[:2], str(place / "study"), *init[2:]], tmp_path, timeout=60,
                                 read_only=(how, place))
            assert refused.returncode == 2 and "read-only" in refused.stderr.lower(), (how, refused.stderr)
            assert len(refused.stderr.strip().splitlines()) == 1, refused.stderr
        seen = zygote.run(["protocol", "check", str(tmp_path / "kept" / "study.toml")], tmp_path, timeout=60,
                          read_only=("bind", tmp_path / "kept"))  # the bound folder's own file, read through it
        assert seen.returncode == 2 and "not valid TOML" in seen.stderr, seen.stderr  # read, not "no such file"
        wrote = zygote.run([*init[:2], str(tmp_path / "ro" / "study"), *init[2:]], tmp_path, timeout=60)
        assert wrote.returncode == 0, wrote.stderr
    assert (tmp_path / "ro" / "study" / "study.toml").is_file() and not (tmp_path / "kept" / "study").exists()
    (tmp_path / "ro" / "mine").write_text("this process writes there too")
