"""awalker_tracker.errors: YAML problems become one-line InputErrors naming where they came from."""
import pytest

from awalker_tracker.errors import InputError, parse_yaml


def test_parse_yaml_returns_the_document() -> None:
    assert parse_yaml("start: {frame: 3}\n", "start.yaml") == {"start": {"frame": 3}}


def test_parse_yaml_error_is_one_line_and_names_the_source() -> None:
    with pytest.raises(InputError) as info:
        parse_yaml("cameras:\n  - name: cam0\n   width: 640\n", "/data/cal.yaml")
    message = str(info.value)
    assert message.startswith("/data/cal.yaml: not valid YAML (")
    assert "\n" not in message and "line 3" in message
