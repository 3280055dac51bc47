"""Errors for bad user input: each names the file or topic and what was expected."""


class InputError(Exception):
    """Bad input from a user (file, topic, parameter); the CLI prints it without a traceback."""
