"""A count is said with its noun by one helper (pairplay/numbers.py `counted`): "1 participant", never
"1 participants". A new user's trial read "1 participants" (`pairplay report`) and the like: every f-string
that printed a count before a fixed plural noun said it wrong for 1. The lint below finds the kind in every
module a user's line can come from."""

from __future__ import annotations

import ast
import re
from pathlib import Path


from pairplay.numbers import counted

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("cli", "core", "gym", "pairplay", "replay", "report", "schemas", "services")
# the nouns a line counts (plural forms); a count before one of them, possibly after one adjective
NOUNS = ("participants|players|users|games|rounds|events|files|seeds|cells|settings|personas|items|policies|turns|"
         "messages|records|notes|times|picks|suggestions|bytes|parts|chunks|entries|workers|sessions|replicates|"
         "arms|states|keys|values|lines|characters|steps|answers|questions|phases|folders|recordings|cards|matches|"
         "updates|samples|runs|threads|processes|cores|actions|codes|names|tilings|features|faces|errors|"
         "rejections|frames|questionnaires|runs")
FIXED_PLURAL = re.compile(rf"^ (?:[a-z]+ )?(?:{NOUNS})\b")


def _constant(node: ast.expr) -> bool:
    """A module constant (MAX_CELLS, geometry.N_STATES, N_STATES - 1): a fixed count, never 1."""
    if isinstance(node, ast.Name):
        return node.id.isupper()
    if isinstance(node, ast.Attribute):
        return node.attr.isupper()
    if isinstance(node, ast.BinOp):
        return _constant(node.left) and isinstance(node.right, ast.Constant)
    return isinstance(node, ast.Constant)


def _measured(value: ast.FormattedValue) -> bool:
    """A number formatted as a measure ({x:.2f} picks per round, {speed:g} times), or a repr ({text!r} names):
    not a count."""
    spec = "".join(v.value for v in value.format_spec.values if isinstance(v, ast.Constant)) if value.format_spec else ""
    return value.conversion == ord("r") or bool(spec.strip(",d"))


# not counts: a phase's `players` is "new" or "all" ("new players")
NOT_COUNTS = {"p.players"}


def _fixed_plurals(path: Path) -> list[str]:
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if not isinstance(node, ast.JoinedStr):
            continue
        for value, after in zip(node.values, node.values[1:]):
            if (isinstance(value, ast.FormattedValue) and isinstance(after, ast.Constant)
                    and isinstance(after.value, str) and FIXED_PLURAL.match(after.value)
                    and not _constant(value.value) and not _measured(value)
                    and ast.unparse(value.value) not in NOT_COUNTS
                    # a count said with its noun already ("{counted(n, 'row')} for answers ...")
                    and not (isinstance(value.value, ast.Call) and ast.unparse(value.value.func).endswith("counted"))):
                found.append(f"{path.relative_to(ROOT)}:{value.lineno}: {{{ast.unparse(value.value)}}}"
                             f"{after.value[:30]!r}")
    return found


def test_counted_says_the_singular_for_1_only():
    assert counted(1, "participant") == "1 participant"
    assert [counted(n, "round") for n in (0, 2)] == ["0 rounds", "2 rounds"]
    assert counted(1, "policy", "policies") == "1 policy" and counted(3, "policy", "policies") == "3 policies"
    assert counted(12345, "event", spec=",") == "12,345 events"


def test_no_count_is_printed_before_a_fixed_plural():
    files = [f for package in PACKAGES for f in sorted((ROOT / package).rglob("*.py"))]
    assert len(files) > 100
    found = [hit for f in files for hit in _fixed_plurals(f)]
    assert not found, "a count before a fixed plural (use pairplay.numbers.counted):\n" + "\n".join(found)
