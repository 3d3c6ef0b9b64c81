"""Command registration placeholder (filled in by the owning module's work)."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    """Adds no command yet."""
