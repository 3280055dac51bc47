"""The ``awalker`` command: one entry point, one module per subcommand.

Every module in ``awalker_tools.commands`` provides ``register(subparsers)``, which adds its
parser and sets ``func`` to a callable ``(args) -> int``; modules are found automatically and
listed alphabetically in ``--help``. User errors (``InputError``) are printed as one line
naming the file or topic, without a traceback, and exit with status 2.
"""
from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

from awalker_tracker.errors import InputError

from awalker_tools import commands


def command_modules() -> list[str]:
    """Names of the subcommand modules in ``awalker_tools.commands``, sorted."""
    return sorted(m.name for m in pkgutil.iter_modules(commands.__path__) if not m.name.startswith("_"))


def version() -> str:
    """The installed awalker_tools package's version."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as package_version

    try:
        return package_version("awalker_tools")
    except PackageNotFoundError:        # run from a source tree that was never installed
        return "unknown (not installed)"


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="awalker",
        description="Physics-based 3D person tracking with the Anthropomorphic Walker (ROS 2).",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {version()}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    subparsers.required = True
    for name in command_modules():
        importlib.import_module(f"awalker_tools.commands.{name}").register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except InputError as exc:
        # One line, however the message was built (YAML parser errors span several lines).
        message = " ".join(str(exc).split())
        print(f"awalker {args.command}: error: {message}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        # Output piped into e.g. `head`, which closed early: not an error of ours.
        sys.stderr.close()
        return 0
    except KeyboardInterrupt as exc:
        # Ctrl-C (130), or `awalker track`'s pipeline.Interrupted: what it wrote, and 128 + the signal's number
        print(f"awalker {args.command}: {' '.join(str(exc).split()) or 'interrupted'}", file=sys.stderr)
        return int(getattr(exc, "exit_status", 130))


if __name__ == "__main__":
    sys.exit(main())
