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
