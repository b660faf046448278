"""``taichi-hair groom``, ``render`` and ``variants`` (being written; none registered yet)."""

from __future__ import annotations


def register(sub) -> None:
    """Add the grooming-tool commands to an argparse subparsers object (none registered yet)."""
