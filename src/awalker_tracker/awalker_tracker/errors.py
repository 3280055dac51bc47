"""Errors for bad user input: each names the file or topic and what was expected."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml


class InputError(Exception):
    """Bad input from a user (file, topic, parameter); the CLI prints it without a traceback."""


def parse_yaml(text: str, where: str) -> Any:
    """The YAML document in ``text``; ``where`` names the file or topic in the one-line error."""
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        detail = " ".join(str(exc).split())
        raise InputError(f"{where}: not valid YAML ({detail})") from None


def read_text_file(path: Path, what: str) -> str:
    """The UTF-8 text of ``path``, a ``what`` (e.g. "body description"); one-line errors for a file that cannot
    be read or is not text (a binary file given as YAML)."""
    try:
        return path.read_bytes().decode("utf-8")
    except FileNotFoundError:
        raise InputError(f"{path}: cannot read {what} ({what} not found)") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read {what} ({exc.strerror})") from None
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: not a text file (byte {exc.start} is not UTF-8); expected a {what} in "
                         "YAML") from None
