"""Subcommands of the awalker CLI; each module has register(subparsers)."""
