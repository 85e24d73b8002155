"""Tables of studies and sweeps: a rich table for the terminal, the same rows as plain text for table.txt."""

from __future__ import annotations

from rich.table import Table


def rich_table(title: str, columns: list[str], rows: list[list[str]], left: tuple[str, ...]) -> Table:
    """Columns named in `left` are left-aligned (text); the rest right-aligned (numbers)."""
    table = Table(title=title)
    for c in columns:
        table.add_column(c, justify="left" if c in left else "right")
    for row in rows:
        table.add_row(*row)
    return table


def plain_table(columns: list[str], rows: list[list[str]]) -> str:
    rows = [columns, *rows]
    widths = [max(len(str(r[i])) for r in rows) for i in range(len(columns))]
    return "\n".join("  ".join(str(c).ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows) + "\n"
