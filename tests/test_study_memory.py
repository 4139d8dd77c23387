"""The study gives a phase's big arrays back to the system when the phase ends (report/study.py
`return_freed_memory`): glibc otherwise raises its mmap threshold to the size of each mapped block
freed, and the next arrays of that size stay resident on the heap after they are freed (the study's
peak was the oracle's freed turns under the evaluations: 211 MiB where no phase needs 190)."""

import subprocess
import sys

import pytest

SNIPPET = """
import sys
import numpy as np
from pairplay.report.study import return_freed_memory

def rss():
    for line in open("/proc/self/status"):
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) // 1024

fixed = return_freed_memory() if sys.argv[1] == "fixed" else False
a = np.ones(20 << 17)  # 20 MiB, mapped; freeing it raises glibc's threshold to 20 MiB (at most 32)
del a
before = rss()
b = np.ones(15 << 17)  # 15 MiB: on the heap once the threshold is raised
del b
print(int(fixed), rss() - before)
"""


def _run(mode: str) -> tuple[int, int]:
    done = subprocess.run([sys.executable, "-c", SNIPPET, mode], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr[-2000:]
    fixed, kept = done.stdout.split()
    return int(fixed), int(kept)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's allocator")
def test_a_freed_phase_array_leaves_the_process():
    fixed, kept = _run("fixed")
    if not fixed:
        pytest.skip("not glibc: mallopt is not there")
    assert kept < 5  # MiB still resident after the 15 MiB array was freed
    # Without the fix glibc kept the 15 MiB resident in 2 of 2 runs alone (the case the fix is for), but
    # not in one run inside the whole suite: its dynamic threshold depends on what the process freed
    # before, so the unfixed case is not asserted; the fix's own bound is.
