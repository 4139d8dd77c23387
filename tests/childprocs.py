"""The child processes of a process under test, read from /proc: a verb's pool workers, found to be killed or
checked for (tests/test_processes_orphan.py, tests/test_worker_lost.py)."""

from pathlib import Path


def children(pid: int) -> list[int]:
    """`pid`'s child processes (of every thread: a pool's workers are started by whichever thread submits)."""
    found = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            found += [int(c) for c in (task / "children").read_text().split()]
        except OSError:
            pass
    return found


def alive(pid: int) -> bool:
    """Running, not a zombie waiting for whoever reaps it (in a container pid 1 may never)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"
