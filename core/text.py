"""Text every store keeps: the one rule for what a stored string may hold.

PostgreSQL's `text` cannot hold NUL (U+0000), and a lone surrogate (U+D800 to U+DFFF on
its own) is not Unicode text at all: neither SQLite nor PostgreSQL can encode it as UTF-8.
Every other character is stored and read back as it was, on every supported database.
The API refuses such text where it arrives (naming the field, with
`server.schemas.TEXT_PATTERN` in the OpenAPI document); the engine refuses a reward note
holding it; the stores refuse it before writing, so no store holds what another cannot.
"""

from __future__ import annotations

import re

UNSTORABLE = re.compile("[\x00\ud800-\udfff]")
"""The characters no supported database stores: NUL and the surrogates."""


def unstorable(text: str) -> str | None:
    """Why `text` cannot be stored, naming the first offending character; None if it can."""
    found = UNSTORABLE.search(text)
    if found is None:
        return None
    char = found.group()
    what = "NUL (U+0000)" if char == "\x00" else f"a lone surrogate (U+{ord(char):04X})"
    return (
        f"{what} at position {found.start()} cannot be stored: text may hold any character "
        "but NUL and lone surrogates"
    )


def check_storable(text: str, what: str) -> str:
    """`text` if it can be stored, else `ValueError` saying why, for `what` (e.g. "a note")."""
    problem = unstorable(text)
    if problem is not None:
        raise ValueError(f"{what}: {problem}")
    return text
