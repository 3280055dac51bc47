"""Subcommands of the awalker CLI; each module has register(subparsers). Argument types they share are here."""
from __future__ import annotations

import argparse
import math


def whole_number(text: str) -> int:
    """argparse type of a count: an integer, also written as 1e5 (``--particles 1e8`` is then refused by its
    range check, which says the range, rather than by argparse)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if not (math.isfinite(value) and value == int(value)):
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}")
    return int(value)
