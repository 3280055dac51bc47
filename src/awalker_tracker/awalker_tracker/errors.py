"""Errors for bad user input: each names the file or topic and what was expected."""
from __future__ import annotations

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
