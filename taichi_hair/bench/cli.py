"""``taichi-hair bench``: speed-against-accuracy studies (being written; no sub-command yet)."""

from __future__ import annotations


def register(sub) -> None:
    """Add the ``bench`` command family to an argparse subparsers object (none registered yet)."""
