"""The tests' command zygote (tests/cli_zygote.py) runs every command it is sent, however many arrive at once.

Requests sent together from several threads reached the zygote in one read of its stdin: it took the
first line and left the rest in sys.stdin's buffer, which select() never reported again, so those
commands waited for the next request (the last ones for ever: a 60 s timeout on the pid). The tests
that start their commands side by side (test_study_guard's refusals beside a server) met it at once.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor, wait

import pytest


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


TEARDOWN = {  # what a command leaves for the interpreter's exit, and what that exit does with it
    "an open file's buffer": ("held = open('out.txt', 'w')\nheld.write('flushed at exit')\n", "", "flushed at exit"),
    "a finalizer": ("class Held:\n    def __del__(self):\n        print('finalized at exit')\nheld = Held()\n",
                    "finalized at exit\n", ""),
    "an atexit handler": ("import atexit\natexit.register(print, 'atexit ran')\n", "atexit ran\n", ""),
    "garbage with a finalizer": ("class Cycle:\n    def __del__(self):\n        print('collected')\n"
                                 "c = Cycle()\nc.me = c\ndel c\n", "collected\n", ""),
    "nothing": ("", "", ""),
}


@pytest.mark.parametrize("left", TEARDOWN)
def test_a_command_ends_as_the_interpreters_exit_would_end_it(tmp_path, left):
    """cli_zygote._exit skips the teardown of the modules (a command's ~0.11 s of CPU, copying every page it
    shares with the zygote) only where that teardown has nothing to do: what the command left (an open file,
    an object with a finalizer, an atexit handler, garbage) is flushed, finalized and run as by the interpreter's
    own exit, and the exit code is the command's. Before, the child's sys.exit left the zygote's gc.freeze in
    force: an open file left in a global was never flushed, a finalizer never ran (a command's write the table
    would not have seen)."""
    import subprocess
    import sys
    from pathlib import Path

    code, out, written = TEARDOWN[left]
    script = tmp_path / "command.py"
    script.write_text(
        f"import gc, sys\nsys.path.insert(0, {str(Path(__file__).parent)!r})\nfrom cli_zygote import _exit\n"
        "gc.freeze()\n" + code + "_exit(3)\n")  # as the zygote: its imports frozen, then the command
    (tmp_path / "out.txt").write_text("")
    r = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert (r.returncode, r.stdout, r.stderr) == (3, out, ""), r
    assert (tmp_path / "out.txt").read_text() == written


def test_a_started_command_is_read_as_it_writes_signalled_and_reaped_as_popen_gives_it(tmp_path):
    """`Zygote.start` (the long-running commands the tests kill or talk to: a router, restarted services,
    SIGKILLed recorders): its first line is read while it runs, a signal reaches it, its exit is Popen's
    (-9 for SIGKILL), and `communicate` gives both streams, or stdout with stderr in it (STDOUT)."""
    import signal
    import subprocess

    from cli_zygote import shared
    router = shared().start(["router", "--listen", "tcp/127.0.0.1:0"], cwd=tmp_path)
    try:
        assert router.stdout.readline().startswith("listening tcp/127.0.0.1:")  # while it runs
        assert router.poll() is None and router.returncode is None
        router.send_signal(signal.SIGKILL)
        assert router.wait(30) == -signal.SIGKILL and router.returncode == -signal.SIGKILL
    finally:
        router.kill()  # (a no-op once reaped: its pid may be another's)
    said = shared().start(["--version"], cwd=tmp_path)
    out, err = said.communicate(timeout=30)
    assert said.returncode == 0 and out.startswith("pairplay ") and err == "", (out, err)
    refused = shared().start(["session", "--rounds", "0"], cwd=tmp_path, stderr=subprocess.STDOUT, text=False)
    out, err = refused.communicate(timeout=30)
    assert refused.returncode == 2 and out.startswith(b"pairplay session: ") and err is None, out
    quiet = shared().start(["--version"], cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    assert quiet.stdout is None and quiet.stderr is None and quiet.wait(30) == 0
