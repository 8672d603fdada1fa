"""Run and campaign ids: the one rule for every place an id enters (import, run.json on read,
the store, the Python API, the web routes).

An id is also a folder or file name (a run folder, an export's default name, a store
folder), so it is held to a strict pattern: 1-100 ASCII letters, digits, ``_`` and ``-``,
starting with a letter or digit. No dot, slash, backslash, space or control character can
appear, so no id can climb out of a folder (``..``), name a hidden file, or end a line.
"""

from __future__ import annotations

import re

__all__ = ["ID_MAX", "ID_PATTERN", "ID_RULE", "id_from_text", "id_problem"]

ID_MAX = 100
ID_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]{0,99}")
ID_RULE = (f"1-{ID_MAX} ASCII letters, digits, '_' or '-', starting with a letter or digit "
           "(no dots, slashes, spaces or control characters)")
_SHOWN = 60


def _shown(value: str) -> str:
    text = repr(value)
    return text if len(text) <= _SHOWN else f"{text[:_SHOWN]}...' ({len(value)} characters)"


def _why(value: str) -> str:
    if value == "":
        return "it is empty"
    if len(value) > ID_MAX:
        return f"it has {len(value)} characters"
    bad = next((c for c in value if not (c.isascii() and (c.isalnum() or c in "_-"))), None)
    if bad is not None:
        names = {"/": "a slash", "\\": "a backslash", ".": "a dot", " ": "a space",
                 "\x00": "a NUL byte", "\n": "a newline", "\r": "a carriage return",
                 "\t": "a tab"}
        return f"it holds {names.get(bad, repr(bad))}"
    return f"it starts with {value[0]!r}"


def id_problem(value: object, kind: str = "run") -> str | None:
    """None if ``value`` is a valid ``kind`` id (``kind``: "run" or "campaign"), else the
    one-line reason: which value, why, and what is allowed."""
    if isinstance(value, str) and ID_PATTERN.fullmatch(value) is not None:
        return None
    if not isinstance(value, str):
        return f"invalid {kind} id {value!r}: not a string; a {kind} id is {ID_RULE}"
    return f"invalid {kind} id {_shown(value)}: {_why(value)}; a {kind} id is {ID_RULE}"


def id_from_text(text: object, fallback: str) -> str:
    """A valid id made from free text (a file name, a campaign name): characters outside
    ``[A-Za-z0-9_-]`` become ``_``, leading ``_``/``-`` are dropped, cut to 100 characters;
    ``fallback`` when nothing usable is left."""
    raw = "" if text is None else str(text)
    name = re.sub(r"[^A-Za-z0-9_-]+", "_", raw).lstrip("_-")[:ID_MAX]
    return name if ID_PATTERN.fullmatch(name) else fallback
