"""``tactbench layout``: inspect taxel layouts."""

from __future__ import annotations

import click


@click.group("layout")
def layout_group() -> None:
    """Inspect and generate taxel layouts."""
