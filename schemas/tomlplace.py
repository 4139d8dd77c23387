"""Where a key of a TOML file belongs, said when it stands at the wrong level.

Rule: a file's tables are named by their headers (`[study]`, `[[phase]]`,
`[phase.learner]`) with the keys each takes. In TOML every key after a
`[table]` line is that table's, so a table written too early (`[phase.learner]`
above the phase's last keys) takes the keys below it, and a key of one table
written under another is a key that table does not have; a table's key written
above the file's first `[table]` line (`robot = "virtual"` above `[study]`) is a
key of the top of the file, which has none of that name. All were reported as
a type error ("Expected `int | float | null`, got `array`") or an unknown field;
`misplaced` says instead which table the key belongs to, `table_not_value` that
a `[table]` stands where a key takes a value. Each returns the message's text
(the reader prefixes the file and the key path), "" when the rule does not
apply.

A line names a place in the user's words (`Written.place`): the `[table]` header
the file wrote above the key, an element of an array of tables by its `id`
(`[[phase]] "phase1" rounds`, never msgspec's `$.phase[0].rounds`), and a key
of a table written inline as a dotted key (`[[phase]] "phase1"
learner.alpha_start`). A value is echoed as the file has it (`Written.typed`:
`rounds = 1_000`, `20.0`), else, where the file's text cannot say it (a value
over several lines), as parsed, through `pairplay.numbers.shown`. Standard
library only.
"""

from __future__ import annotations

import re
import tomllib
from typing import Collection, Mapping, Sequence

from pairplay.numbers import shown
from .nesting import toml_loads

# the keys above a file's first `[table]` line: a place named in words, where a table is named by its header
TOP = "the top of the file"


def misplaced(key: str, here: str, tables: Mapping[str, Collection[str]], enclosing: Sequence[str] = (),
              table: bool = False) -> str:
    """Why `key`, written under the table `here`, is not that table's: it belongs to `enclosing` (the
    tables `here` is inside, innermost first: written above the `here` line, it would be theirs), or to
    another table of the file (all of them named when `here` is the top of the file: its key is above every
    table's line); "" if `here` takes it or no table does. `table`: what stands there is a table (a
    `[study.grid]` line), so the advice moves the table, not a `key = ...` line."""
    if key in tables.get(here, ()):
        return ""
    what = f"the `{key}` table" if table else f"`{key} = ...`"
    for header in enclosing:
        if key in tables.get(header, ()):
            where = (f"write it as its own [{key}] table, not inside {here}" if table and not header.startswith("[") else
                     f"move {what} above that line")
            return (f"`{key}` belongs {_to(header)}, not to {here}: the keys after a {here} line are that "
                    f"table's; {where}")
    owners = [header for header, keys in tables.items() if header != here and key in keys]
    if owners and not here.startswith("["):
        # a table's key written above the file's first [table] line (`robot = ...` above [study])
        tables_ = " or ".join(owners)
        return (f"`{key}` belongs to {tables_}, not {_to(here)} (above its first [table] line): "
                f"move {what} below the {tables_} line")
    if owners:
        return f"{here} has no key `{key}`; `{key}` is a key of {owners[0]}"
    return ""


def table_not_value(key: str, table: str, here: str) -> str:
    """The line's text for a `table` header (`[study.seed]`) standing where `key` of the table `here` takes
    a value."""
    place = f"among the keys of {here}" if here.startswith("[") else f"at {here}"
    return f"{table} is a table, where `{key}` takes a value: write `{key} = ...` {place}"


def _to(header: str) -> str:
    """"to [study]", but "at the top of the file": a header, or a place named in words."""
    return f"to {header}" if header.startswith("[") else f"at {header}"


def header(path: Sequence) -> str:
    """A table's header as the file writes it: ("phase", 0, "learner") -> [phase.learner], ("phase", 0)
    -> [[phase]]; () -> the top of the file."""
    if not path:
        return TOP
    names = ".".join(_bare(t) for t in path if isinstance(t, str))
    return f"[[{names}]]" if isinstance(path[-1], int) else f"[{names}]"


def _bare(key: str) -> str:
    """A key as TOML writes it: bare if it can be, else quoted."""
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else '"' + key.replace('"', '\\"') + '"'


_KEY = r'(?:[A-Za-z0-9_-]+|"(?:[^"\\]|\\.)*"|\'[^\']*\')'
_DOTTED = rf"{_KEY}(?:\s*\.\s*{_KEY})*"


def _names(dotted: str) -> tuple[str, ...]:
    """`a."b.c".d` -> ("a", "b.c", "d")."""
    out = []
    for m in re.finditer(_KEY, dotted):
        k = m.group(0)
        out.append(toml_loads(f"k = {k}")["k"] if k[0] in "\"'" else k)
    return tuple(out)


def _outside(text: str):
    """(index, character, depth) of each character of `text` outside its strings; depth counts the arrays and
    inline tables open after it."""
    depth, quote, escaped = 0, "", False
    for i, c in enumerate(text):
        if quote:
            escaped, quote = (not escaped and c == "\\" and quote == '"'), ("" if c == quote and not escaped else quote)
            continue
        if c in "\"'":
            quote = c
            continue
        depth += (c in "[{") - (c in "]}")
        yield i, c, depth


def _split(text: str) -> list[str]:
    """`text` cut at each top-level comma (not inside a string, array or inline table), up to a comment."""
    parts, start, end = [], 0, len(text)
    for i, c, depth in _outside(text):
        if c == "#" and depth == 0:
            end = i
            break
        if c == "," and depth == 0:
            parts.append(text[start:i])
            start = i + 1
    parts.append(text[start:end])
    return parts


def _closed(text: str) -> int:
    """The length of the array or inline table `text` starts with, 0 if it does not close on its line."""
    return next((i + 1 for i, c, depth in _outside(text) if c in "]}" and depth == 0), 0)


class Written:
    """What a TOML text wrote where (module rule): each value's text by its key path (indices of arrays of
    tables and of arrays as ints) and the tables it wrote as `[header]` lines. A line it cannot follow (a
    value over several lines) leaves its values out: `typed` then says the parsed value."""

    def __init__(self, text: str, raw: object = None):
        self.raw = raw  # the TOML read (tomllib): an element's id
        self.values: dict[tuple, str] = {}
        self.headers: set[tuple] = set()
        counts: dict[tuple, int] = {}

        def resolve(names: tuple[str, ...]) -> tuple:
            path: tuple = ()
            for name in names:
                path += (name,)
                if path in counts:  # an array of tables: its latest element
                    path += (counts[path],)
            return path
        table: tuple = ()
        closing = ""  # the delimiter of a multi-line string being skipped (its lines are no keys)
        for line in text.splitlines():
            s = line.strip()
            if closing:
                closing = "" if closing in s else closing
                continue
            m = re.fullmatch(rf"\[\[\s*({_DOTTED})\s*\]\]\s*(#.*)?", s)
            if m:
                names = _names(m.group(1))
                key = resolve(names[:-1]) + (names[-1],)
                counts[key] = counts.get(key, -1) + 1
                table = key + (counts[key],)
                self.headers.add(table)
                continue
            m = re.fullmatch(rf"\[\s*({_DOTTED})\s*\]\s*(#.*)?", s)
            if m:
                table = resolve(_names(m.group(1)))
                self.headers.add(table)
                continue
            m = re.match(rf"({_DOTTED})\s*=\s*(.*)$", s)
            if m:
                value = m.group(2).strip()
                if value[:3] in ('"""', "'''") and value[:3] not in value[3:]:
                    closing = value[:3]
                    continue
                self._value(table + _names(m.group(1)), value)

    def _value(self, path: tuple, text: str) -> None:
        text = _split(text)[0].strip() if text[:1] not in "[{" else text.strip()
        if text[:1] in "[{":
            close = "]" if text[0] == "[" else "}"
            length = _closed(text)
            if not length:
                return  # over several lines: not followed
            inner = text[1:length - 1]
            self.values[path] = text[:length]
            items = [p for p in _split(inner) if p.strip()]
            for n, item in enumerate(items):
                if close == "]":
                    self._value(path + (n,), item.strip())
                else:
                    m = re.match(rf"\s*({_DOTTED})\s*=\s*(.*)$", item, re.S)
                    if m:
                        self._value(path + _names(m.group(1)), m.group(2))
            return
        if text:
            self.values[path] = text

    def typed(self, path: Sequence, value: object) -> str:
        """`value`, the file's value at `path`, as the file has it (`1_000`, `20.0`, `"x"`), else as parsed
        (`shown`). The text is checked: it must read back as `value`."""
        text = self.values.get(tuple(path))
        if text is not None:
            try:
                read = toml_loads(f"v = {text}")["v"]
            except tomllib.TOMLDecodeError:
                read = None
            if read == value or (read != read and value != value):  # nan is nan
                return text
        return shown(value)

    def place(self, path: Sequence) -> str:
        """`path` (keys, and ints for array elements) in the user's words (module rule): the header of the
        deepest table the file wrote above it, each array element named by its id, then the rest as a
        dotted key: `[[phase]] "phase1" rounds`, `[study] seed`, `[[phase]] "phase1" learner.alpha_start`,
        `robot` (at the top of the file)."""
        path = tuple(path)
        n = max((k for k in range(len(path) + 1) if path[:k] in self.headers), default=0)
        head, rest = path[:n], path[n:]
        words = [header(head)] if head else []
        for k, token in enumerate(head):
            if isinstance(token, int):
                words.append(self._element(head[:k + 1]) if k == len(head) - 1
                             else f"of {self._element(head[:k + 1])}")
        key = ".".join(_bare(t) if isinstance(t, str) else f"[{t}]" for t in rest).replace(".[", "[")
        return " ".join(words + ([key] if key else []))

    def _element(self, path: tuple) -> str:
        """An element of an array of tables by its id (`"phase1"`), else by its place (`#2`: the second)."""
        node = self._at(path)
        ident = node.get("id") if isinstance(node, dict) else None
        siblings = self._at(path[:-1])
        twice = [e.get("id") for e in siblings if isinstance(e, dict)].count(ident) > 1 if isinstance(siblings, list) else True
        if isinstance(ident, str) and ident and not twice:  # an id given twice names neither: its place does
            return '"' + ident + '"'
        return f"#{path[-1] + 1}"

    def _at(self, path: tuple) -> object:
        """The TOML read's value at `path`, None if it has none."""
        node: object = self.raw
        for token in path:
            node = (node[token] if isinstance(node, list) and token < len(node) else None) if isinstance(token, int) \
                else (node.get(token) if isinstance(node, dict) else None)
        return node
