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
apply. Standard library only.
"""

from __future__ import annotations

from typing import Collection, Mapping, Sequence

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
