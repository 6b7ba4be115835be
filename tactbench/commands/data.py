"""``tactbench data``: inspect, simulate and preview datasets."""

from __future__ import annotations

import click


@click.group("data")
def data_group() -> None:
    """Inspect, simulate and preview datasets."""
