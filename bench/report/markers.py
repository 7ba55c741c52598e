"""Generated tables in markdown files: the text between ``<!-- NAME: start -->`` and ``<!-- NAME: end -->``."""

from __future__ import annotations


def markers(name: str) -> tuple[str, str]:
    """The start and end markers of the table named ``name``."""
    return f"<!-- {name}: start -->", f"<!-- {name}: end -->"


def replace_between_markers(doc: str, table: str, start: str, end: str) -> str:
    """``doc`` with the text between the markers ``start`` and ``end`` (both kept) replaced by ``table``; a
    ValueError when the markers are missing or out of order."""
    i, j = doc.find(start), doc.find(end)
    if i < 0 or j < i:
        raise ValueError(f"no {start} ... {end} pair to put the table between")
    return doc[:i + len(start)] + "\n" + table.rstrip("\n") + "\n" + doc[j:]
