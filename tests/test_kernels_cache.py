"""numba's on-disk cache of core/kernels.py works where the installed package is read-only.

numba writes its cache beside the source (core/__pycache__) when it can, else in
the user-wide cache dir (~/.cache/numba), unless NUMBA_CACHE_DIR names one. Here
core/ is bind-mounted read-only in a private mount namespace the test makes, and
HOME is a fresh folder: the first process compiles into HOME's cache, the second
loads from it.
"""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

CORE = Path(__file__).resolve().parents[1] / "core"
SNIPPET = """
import numpy as np
from pairplay.core import kernels
out = np.empty(1, dtype=np.int64)
kernels.pick_batch(np.array([6]), np.array([0.9]), out)
s = kernels.pick_batch.stats
print(int(out[0]), sum(s.cache_hits.values()), sum(s.cache_misses.values()), s.cache_path)
"""


def _run_read_only(home: Path) -> list[str]:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["HOME"] = str(home)
    script = f'mount --bind -o ro "{CORE}" "{CORE}" && exec "{sys.executable}" -c "$0"'
    done = subprocess.run(["unshare", "-m", "--propagation", "private", "sh", "-c", script, SNIPPET],
                          capture_output=True, text=True, env=env, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout.split()


@pytest.mark.skipif(os.geteuid() != 0 or shutil.which("unshare") is None, reason="needs root and unshare")
def test_a_read_only_package_caches_its_kernels_in_the_user_cache(tmp_path):
    card, hits, misses, path = _run_read_only(tmp_path)
    assert card == "2" and misses == "1" and hits == "0"  # bit 2 is the last of 0b110: compiled
    assert Path(path).is_relative_to(tmp_path / ".cache" / "numba") and any(Path(path).glob("*.nbi"))
    card, hits, misses, _ = _run_read_only(tmp_path)
    assert card == "2" and hits == "1" and misses == "0"  # the second process loads it
