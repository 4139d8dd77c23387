"""The mistakes a user can make, as exception kinds the command line knows.

Rule: code anywhere in pairplay raises a `UserError` (or a subclass) for a
mistake the user can fix: a missing or unreadable input, an output that
already exists, an option out of range, a bus endpoint that cannot be used.
Its message says what is wrong and `where` says which file, option or
endpoint. `pairplay.cli.main` turns it into ONE line on stderr,
`pairplay <verb>: <what> (<where>)`, and exit status 2; anything else is a
bug of ours and keeps its traceback. Standard library only (every layer
imports this).
"""

from __future__ import annotations

import re
import shlex


class UserError(Exception):
    """A mistake the user can fix. `str(err)` says what, `err.where` says where ('' if nowhere).

    `fix`, with the `option` it names (`fix="--force replaces it", option="--force"`), is a way out
    that only some verbs offer: code below the command line does not know which verb runs it, so
    the verb that shows the line gives its options (`line(options)`) and a fix naming an option it
    lacks is left out (a hint must name only what exists where it is read: tests/test_hints.py)."""

    def __init__(self, what: str, where: str | object = "", *, fix: str = "", option: str = ""):
        super().__init__(what)
        self.what = what
        self.where = str(where) if where not in (None, "") else ""
        self.fix, self.option = fix, option

    def line(self, options: frozenset[str] | set[str] | None = None) -> str:
        """What and where, on one line: `where` is added unless the text names it already, as a
        whole name (a folder `here` is not named by "there", nor `out` by "out/study"); then the
        `fix`, unless `options` (those of the verb showing the line; None: every option) lack its `option`.
        A control character of either (a path's or a value's newline) is shown escaped (`escaped`), never
        folded into a space: `what` often holds a path (`<folder>: not a study folder`), and
        `/tmp/no<TAB>su<NEWLINE>ch` said as "/tmp/no su ch" named another path (trial32 F). Folding was the
        first way to keep the line one line, before `escaped`; a library's message that may span lines
        is folded where it enters a line (`folded`), and our own words hold no newline."""
        text = escaped(self.what)
        if self.fix and (options is None or not self.option or self.option in options):
            text = f"{text}; {self.fix}"
        where = escaped(self.where)
        return f"{text} ({where})" if where and not names(text, where) else text

    def __str__(self) -> str:
        """The line wherever it is shown with no verb's options known (a log, an event's error field, a
        web page): where it is, and no fix naming an option (none can be given there)."""
        return self.line(frozenset())


class InputError(UserError, ValueError):
    """An input is missing, empty or not what the verb needs."""


class ArgumentError(InputError, TypeError):
    """A public function was given a value of the wrong kind (pairplay/arguments.py): a number for a
    path, a path for a read policy, a bool for an integer. Both an InputError and a TypeError."""


class OutputError(UserError):
    """An output cannot be written where asked (exists, is a folder, read-only, collides)."""


class OptionError(UserError, ValueError):
    """An option's value is out of its range or meaningless with the others."""


class WorkerLost(Exception):
    """Work handed to another process was lost: a pool's worker process died (the OOM killer's SIGKILL),
    a Dask scheduler stopped answering, a cell failed on a Dask worker. Not the user's mistake and not a
    bug of ours: `pairplay.cli.main` says `str(err)` on ONE line, what is kept after it, and exits 1
    (README's exit table: a verb that lost a part it needs, as a session that lost a service). The
    message says what happened in our words; the verb that knows what it kept adds that."""


# what a line must not hold raw: control characters (C0, DEL, C1: a newline split "one line" in two, an ESC
# drives the terminal), the Unicode line and paragraph separators, and lone surrogates (a file name's bytes
# that are not UTF-8, as os.fsdecode gives them: printing one raised UnicodeEncodeError)
_UNSHOWABLE = re.compile("[\x00-\x1f\x7f-\x9f\u2028\u2029\ud800-\udfff]")


def unshowable(text: str) -> re.Match | None:
    """The first character of `text` that `escaped` would escape (None: it shows as it is): what a free text a
    user gives (a reason, a name) is refused for, since it would land raw in a CSV or a report."""
    return _UNSHOWABLE.search(text)


def escaped(text: object) -> str:
    """`text` (a path, a user's value, a line holding them) as one line shows it: each control character,
    line separator or lone surrogate as its Python escape (`\\n`, `\\x1b`, `\\udcff`), the rest as it is.
    Every line pairplay prints with a path or a value in it goes through this (trial28 F10: `rebuild` of
    `x\\ny.mcap` printed its result lines split at the newline)."""
    text = str(text)
    if _UNSHOWABLE.search(text) is None:  # the usual case: nothing to escape
        return text
    return _UNSHOWABLE.sub(lambda m: m.group().encode("unicode_escape", "backslashreplace").decode("ascii")
                           if not 0xD800 <= ord(m.group()) <= 0xDFFF else f"\\u{ord(m.group()):04x}", text)


def folded(text: object) -> str:
    """A library's message (an exception's text we did not write: Dask's, Zenoh's, a viewer's) on one line,
    its newlines and runs of blanks folded into one space. Never for a path or a user's value: those are
    `escaped`, so the line names the very path (a folded tab or newline names another)."""
    return " ".join(str(text).split())


def command_word(text: object) -> str:
    """`text` (a path, a user's value) as one word of a command a line suggests (`pairplay report <folder>`
    writes the report): typed as shown, it is the same path. `shlex.quote`d (a space or a `$` neither splits nor
    expands it); holding what `escaped` would escape, in the $'...' form of bash and zsh with those escapes
    instead, so the line stays one line and the word still the path (trial29 F4: `protocol pilot`'s last line
    suggested `pairplay report we ird` split over three lines: typed, not the folder)."""
    text = str(text)
    if _UNSHOWABLE.search(text) is None:
        return shlex.quote(text)
    inner = text.replace("\\", "\\\\").replace("'", "\\'")
    return "$'" + _UNSHOWABLE.sub(_shell_escape, inner) + "'"


def _shell_escape(m: re.Match) -> str:
    """One unshowable character as $'...' gives it back: a lone surrogate of a file name's byte that is not
    UTF-8 (os.fsdecode's U+DC80-U+DCFF) as that byte, C1 and the separators as their code point."""
    c = ord(m.group())
    if c in _SHELL_NAMED:
        return _SHELL_NAMED[c]
    if c < 0x80 or 0xDC80 <= c <= 0xDCFF:
        return f"\\x{c & 0xFF:02x}"
    return f"\\u{c:04x}"


_SHELL_NAMED = {9: "\\t", 10: "\\n", 13: "\\r"}


def names(text: str, where: str) -> bool:
    """Whether `text` holds `where` as a whole name: not inside a longer word, path or option."""
    return re.search(rf"(?<![\w./-]){re.escape(where)}(?![\w/-]|\.\w)", text) is not None


def out_of_threads(err: BaseException) -> bool:
    """Whether `err` is Python's refusal to start a thread ("can't start new thread": the process's
    address-space limit, `ulimit -v`, or the machine's thread limit ran out; zenoh-python's subscriber
    threads raise it too). The user's setup, like running out of memory: the command line says one
    line, exit 2 (cli/main.py), never a traceback."""
    return isinstance(err, RuntimeError) and "can't start new thread" in str(err)
