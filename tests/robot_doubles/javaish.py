"""Java behaviours the IrisTK doubles need, written from the Java documentation, not from our client.

Rule: each function does what the named Java call does on the inputs the doubles
meet: String.trim, String.split(" ") (trailing empty strings removed),
Integer.parseInt (an optional sign, then Unicode decimal digits: Character.digit
accepts every Nd digit, so "٣" is 3, while "²" is refused; int32 range), and
IrisTK's NameFilter (core/src/iristk/util/NameFilter.java: compile's character
check at line 77, ";" items of " "-separated patterns at lines 47-56 and 119-121,
the last matching pattern of an item decides at lines 142-150, "*" and "**" at
lines 133-137). The NameFilter here is a hand-written matcher (no regex), so it
is independent of the client's regex-based one.
"""

from __future__ import annotations

import unicodedata

_FILTER_OK = set("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789_!.*; ")


def java_trim(text: str) -> str:
    """String.trim: strip every character <= U+0020 at both ends."""
    start, end = 0, len(text)
    while start < end and text[start] <= " ":
        start += 1
    while end > start and text[end - 1] <= " ":
        end -= 1
    return text[start:end]


def java_split_space(text: str) -> list[str]:
    """String.split(" "): split on single spaces, trailing empty strings removed."""
    parts = text.split(" ")
    while len(parts) > 1 and parts[-1] == "":
        parts.pop()
    if parts == [""]:
        return [""]
    return parts


def java_parse_int(text: str) -> int:
    """Integer.parseInt(text, 10); ValueError where Java throws NumberFormatException."""
    if not text:
        raise ValueError("empty")
    sign, digits = 1, text
    if text[0] in "+-":
        sign, digits = (-1 if text[0] == "-" else 1), text[1:]
    if not digits:
        raise ValueError("sign only")
    value = 0
    for ch in digits:
        if unicodedata.category(ch) != "Nd":
            raise ValueError(f"not a digit: {ch!r}")
        value = value * 10 + unicodedata.decimal(ch)
    value *= sign
    if not -(2 ** 31) <= value < 2 ** 31:
        raise ValueError("out of int range")
    return value


class JavaNameFilter:
    """IrisTK's NameFilter, as a hand-written matcher; ValueError where compile() throws."""

    def __init__(self, spec: str) -> None:
        if not set(spec) <= _FILTER_OK:
            raise ValueError(f"NamePattern illegal: {spec}")
        self.items: list[list[str]] = []
        for item in _split_items(java_trim(spec)):
            patterns = [p for p in java_trim(item).split(" ") if p]
            if patterns:
                self.items.append(patterns)

    def __str__(self) -> str:  # NameFilter.toString (lines 85-93, 153-160)
        return ";".join(" ".join(item) for item in self.items)

    def combine(self, other: "JavaNameFilter") -> "JavaNameFilter":
        """NameFilter.combine (lines 98-106): ALL absorbs, otherwise the items add up."""
        if str(self) == "**" or str(other) == "**":
            return JavaNameFilter("**")
        combined = JavaNameFilter("")
        combined.items = self.items + other.items
        return combined

    def accepts(self, name: str) -> bool:
        for item in self.items:
            accepts = all(p.startswith("!") for p in item)
            for pattern in item:
                include = not pattern.startswith("!")
                if _match(pattern if include else pattern[1:], name):
                    accepts = include
            if accepts:
                return True
        return False


def _split_items(text: str) -> list[str]:
    """split(" *; *") with Java's trailing-empty removal."""
    items = [piece.strip(" ") for piece in text.split(";")]
    while len(items) > 1 and items[-1] == "":
        items.pop()
    return items


def _match(pattern: str, name: str) -> bool:
    """Whole-name match: "**" any run (not line terminators), "*" any run without dots, else literal."""
    if not pattern:
        return not name
    if pattern.startswith("**"):
        rest = pattern[2:]
        for i in range(len(name) + 1):
            if i and name[i - 1] in "\n\r\u0085\u2028\u2029":
                return False
            if _match(rest, name[i:]):
                return True
        return False
    if pattern[0] == "*":
        rest = pattern[1:]
        for i in range(len(name) + 1):
            if i and name[i - 1] == ".":
                return False
            if _match(rest, name[i:]):
                return True
        return False
    return bool(name) and name[0] == pattern[0] and _match(pattern[1:], name[1:])
