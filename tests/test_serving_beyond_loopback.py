"""Serving beyond loopback in clear text is said, the same way by every verb that serves pages (trial27 F9).

A new user's trial: `protocol serve --listen 0.0.0.0:0` served the console, whose token exports and deletes
participants' data, over plain HTTP with an empty stderr, while `lab` warned (the README promises both); and
both printed http://127.0.0.1:PORT, which the touch screen cannot open. Real processes on a real socket: each
verb's stderr holds the one warning, and the URL it prints names this machine's address (services/lab/reach.py),
which answers.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import urllib.request
from pathlib import Path
from urllib.parse import urlsplit

import pytest

from pairplay.replay.studydata import StudyData
from pairplay.services.lab.reach import reachable_host

STUDY = Path(__file__).parent / "data" / "pilot-study.toml"
WARNING = "warning: serving beyond loopback without TLS (README: serving the board beyond loopback)"


def _served(args: list[str], tmp_path: Path, line_starts: str) -> tuple[str, str]:
    """(the URL after `line_starts` on stdout, stderr) of `python -m pairplay ARGS`, stopped by SIGTERM once it
    printed that line and the URL answered."""
    err = tmp_path / "stderr"
    with open(err, "w") as e:
        proc = subprocess.Popen([sys.executable, "-m", "pairplay", *args], cwd=tmp_path, stdout=subprocess.PIPE,
                                stderr=e, text=True)
    try:
        for line in proc.stdout:
            if line.startswith(line_starts):
                url = line.split(": ", 1)[1].strip()
                break
        else:
            pytest.fail(f"no {line_starts!r} line: {err.read_text()}")
        with urllib.request.urlopen(url, timeout=30) as answer:  # the printed URL opens, from outside loopback too
            assert answer.status == 200
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=60)
    return url, err.read_text()


@pytest.mark.parametrize("verb", ["protocol serve", "lab"])
def test_every_verb_serving_pages_beyond_loopback_without_tls_warns_and_prints_a_reachable_url(tmp_path, verb):
    if verb == "lab":
        args, line = ["lab", "--participant", "human:p1", "--out", "rec", "--listen", "0.0.0.0:0"], "board:"
    else:
        StudyData.create(tmp_path / "study", STUDY)
        args, line = ["protocol", "serve", "study", "--listen", "0.0.0.0:0"], "experimenter console:"
    url, err = _served(args, tmp_path, line)
    assert f"pairplay {verb}: {WARNING}" in err.splitlines(), err
    assert urlsplit(url).hostname == reachable_host("0.0.0.0").strip("[]"), url
    if reachable_host("0.0.0.0") != "127.0.0.1":  # a machine with a network: not the touch screen's own loopback
        assert urlsplit(url).hostname != "127.0.0.1"


def test_loopback_and_tls_owe_no_warning():
    from pairplay.services.lab.reach import plain_beyond_loopback

    assert [plain_beyond_loopback(h, tls) for h, tls in [("127.0.0.1", False), ("127.0.0.2", False), ("::1", False),
                                                          ("localhost", False), ("0.0.0.0", True)]] == [None] * 5
    assert plain_beyond_loopback("0.0.0.0", False) == plain_beyond_loopback("::", False) == WARNING
