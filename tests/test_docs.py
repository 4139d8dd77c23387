"""The README's promises: its event catalogue matches the schemas, its commands exist."""

import re
from pathlib import Path

from pairplay.schemas import catalogue
from pairplay.schemas.events import EVENT_TYPES
from pairplay.cli.main import VERBS

README = Path(__file__).resolve().parents[1] / "README.md"


def test_every_event_is_catalogued_and_the_readme_is_current():
    assert {t.__struct_config__.tag for t in EVENT_TYPES} == set(catalogue.CATALOGUE)
    text = README.read_text()
    assert catalogue.inject(text) == text, "run: python -m pairplay.schemas.catalogue --write README.md"


def test_every_verb_the_readme_uses_exists():
    text = README.read_text()
    code = re.findall(r"```.*?```", text, re.DOTALL) + re.findall(r"`[^`\n]+`", text)
    used = {verb for block in code for verb in re.findall(r"pairplay ([a-z]+)", block)}
    assert "study" in used and used <= set(VERBS), used - set(VERBS)


ARCHITECTURE = README.parent / "docs" / "architecture.md"


def test_the_architecture_diagram_is_drawn_from_the_catalogue_and_current():
    assert set(catalogue.FLOW) == set(catalogue.CATALOGUE), "every event needs a FLOW row in schemas/catalogue.py"
    text = ARCHITECTURE.read_text()
    assert catalogue.inject_flow(text) == text, "run: python -m pairplay.schemas.catalogue --write README.md"
    for tag in catalogue.CATALOGUE:
        assert f"-- {tag} -->" in text, f"{tag} is missing from docs/architecture.md's diagram"


def test_every_event_type_has_a_trust_rule_agreeing_with_its_publishers():
    """A new event type without a PUBLISHERS row is refused by every guard ("no event type"): LSPIUpdated was."""
    from pairplay.schemas.trust import PUBLISHERS, publisher_refusal

    assert set(PUBLISHERS) == set(catalogue.CATALOGUE)
    for tag, (publishers, _) in catalogue.FLOW.items():
        for source in publishers:
            if source != "any service":
                assert publisher_refusal(tag, source) is None, (tag, source)


def test_a_file_the_readme_shows_is_shown_as_it_is():
    """A listing whose first line names a file of the repository (`# pairplay sweep examples/X.toml`,
    `# examples/X.toml`) is that file, byte for byte: the sweep grid shown had lost three settings and
    said "two personas" of three (a researcher's trial)."""
    text = README.read_text()
    shown = 0
    for block in re.findall(r"```[a-z]*\n(.*?)```", text, re.DOTALL):
        first = block.split("\n", 1)[0]
        named = re.fullmatch(r"# (?:pairplay \w+ )?((?:examples|docs|tests/data)/[\w./-]+)", first)
        if named and (README.parent / named.group(1)).is_file():
            assert block == (README.parent / named.group(1)).read_text(), named.group(1)
            shown += 1
    assert shown >= 1


def test_the_walkthroughs_listing_says_what_a_fresh_folder_holds():
    """A new user's trial: the walkthrough's `ls recordings/  # ... beside samples/` is wrong in a fresh folder
    (its sessions make recordings/ with their files alone; samples/ is the checkout's committed recordings).
    The comment names samples/ only as what a checkout of pairplay holds besides."""
    line = next(x for x in README.read_text().splitlines() if x.startswith("ls recordings/"))
    said = line.split("#", 1)[1]
    assert "blind-g0.mcap" in said and "deaf-g1.mcap" in said, line
    assert "samples/" not in said or "in a checkout" in said, line


def test_the_readmes_way_to_watch_a_replay_views_it_whole(tmp_path):
    """A new user's trial: the README said to attach `pairplay view --session S --connect ENDPOINT` to the
    endpoint `pairplay replay REC` prints; a small recording replays in half a second at the default speed, and
    the view then found no bus (exit 2). The README's two commands, as written (the port a free one, the
    recording a copy of a sample under the README's name), in two real processes: the view, once it says it
    listens, gets every event the replay published."""
    import os
    import shlex
    import shutil
    import socket
    import subprocess
    import sys

    text = README.read_text()
    view_line = next(line for line in text.splitlines() if line.startswith("pairplay view --session replay1 --listen"))
    replay_line = next(line for line in text.splitlines() if line.startswith("pairplay replay ") and "--as replay1" in line)
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]

    def argv(line: str) -> list[str]:
        words = shlex.split(line.split("#")[0].replace("7450", str(port)))
        assert words[0] == "pairplay"
        return [sys.executable, "-m", "pairplay", *words[1:]]

    recording = next(w for w in shlex.split(replay_line.split("#")[0]) if w.endswith(".mcap"))
    (tmp_path / recording).parent.mkdir(parents=True, exist_ok=True)
    sample = README.parent / "recordings" / "samples" / "sim-helmut-fmt2.mcap"
    shutil.copy(sample, tmp_path / recording)
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    view = subprocess.Popen(argv(view_line), cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env)
    try:
        for line in view.stderr:  # -v: the view says when it listens
            if "listening to session replay1" in line:
                break
        replay = subprocess.run(argv(replay_line), cwd=tmp_path, capture_output=True, text=True, timeout=300, env=env)
        assert replay.returncode == 0, replay.stderr
        replayed = int(replay.stdout.split("replayed ")[1].split(" ")[0])
        out, _ = view.communicate(timeout=300)
    finally:
        if view.poll() is None:
            view.kill()
            view.wait()
    assert view.returncode == 0 and out.startswith(f"saved recordings/replay1.rrd: {replayed} events, 0 notes"), out
