"""Printing Rich tables from the command line, whole even when stdout is not a terminal."""

from __future__ import annotations

from typing import IO

from rich.console import Console
from rich.table import Table


def print_table(out: IO[str], table: Table) -> Console:
    """Print `table` to `out`; returns the console used, for what follows it.

    A pipe or a file has no width of its own, and Rich's 80 columns would cut words in
    half: there the console is as wide as the table needs.
    """
    console = Console(file=out)
    wide = console.measure(table, options=console.options.update_width(1000)).maximum
    if not console.is_terminal and wide > console.width:
        console = Console(file=out, width=wide)
    console.print(table)
    return console
