"""Output folders and files: a command never deletes or overwrites a file it did not write in that run.

A command that writes a folder (``awalker track``, ``demo``, ``synth``) takes it through
``prepare_output_dir``: the folder must be new or empty. With ``force`` the files a previous run listed in the
folder's ``run.yaml`` (key ``written``, paths relative to the folder) are removed to be written again, and every
other file stays; one of those in the way of this run's outputs stops it. After the run, ``record_written``
lists in ``run.yaml`` the files it wrote (every file in the folder but the ones kept), so that the next
``--force`` knows them. Commands that add to a run's folder (``eval``, ``report``) may replace only the files
its ``run.yaml`` lists (``check_may_write``) and add theirs to the list (``add_written``). Every refusal is an
``InputError`` naming the path and what was expected, before any work is done.
"""
from __future__ import annotations

import tempfile
from collections.abc import Collection, Iterable
from pathlib import Path

import yaml

from awalker_tracker.errors import InputError, parse_yaml, read_text_file

RUN_FILE = "run.yaml"
#: The bag a tracking run writes: image features, posteriors and poses (`awalker track`).
RESULT_BAG = "result.bag"
#: The key of ``run.yaml`` listing the files the run wrote, relative to its folder.
WRITTEN_KEY = "written"
#: The key of ``run.yaml`` saying why a run stopped before its end (absent when it ran to the end).
INCOMPLETE_KEY = "incomplete"


def output_path(text: str | Path, option: str) -> Path:
    """The path an option names; a blank one (which ``Path`` would read as the current folder) is refused."""
    if str(text).strip() == "":
        raise InputError(f"{option} '': expected a path")
    return Path(text)


def files_under(folder: Path) -> set[Path]:
    """Every file (and symbolic link) below ``folder``, relative to it."""
    return {p.relative_to(folder) for p in folder.rglob("*") if p.is_file() or p.is_symlink()}


def read_run_file(folder: Path) -> dict:
    path = folder / RUN_FILE
    if not path.is_file():
        return {}
    info = parse_yaml(read_text_file(path, "run.yaml of an awalker run"), str(path))
    if not isinstance(info, dict):
        raise InputError(f"{path}: expected a YAML mapping (the run.yaml of an awalker run)")
    return info


def incomplete_reason(folder: Path) -> str | None:
    """Why the run in ``folder`` stopped early (its run.yaml's ``incomplete``: an error, or SIGINT / SIGTERM), or
    None: it ran to the end (or has no run.yaml)."""
    reason = read_run_file(folder).get(INCOMPLETE_KEY)
    return None if reason is None else str(reason)


def listed_outputs(folder: Path) -> set[Path]:
    """The files ``folder/run.yaml`` lists as its run's own (none without a run.yaml or a list)."""
    written = read_run_file(folder).get(WRITTEN_KEY) or []
    where = folder / RUN_FILE
    if not isinstance(written, list):
        raise InputError(f"{where}: '{WRITTEN_KEY}' must be a list of file paths relative to {folder}")
    listed = set()
    for entry in written:
        path = Path(str(entry))
        if path.is_absolute() or ".." in path.parts or not path.parts:
            raise InputError(f"{where}: '{WRITTEN_KEY}' entry {entry!r}: expected a path inside {folder}")
        listed.add(path)
    return listed


def _check_writable_folder(folder: Path, label: str) -> None:
    """``folder`` (existing) takes new files: a probe file is created there and removed at once; ``label``
    starts the error (the option and the path it names)."""
    try:
        with tempfile.NamedTemporaryFile(dir=folder, prefix=".awalker_probe_"):
            pass
    except OSError as exc:
        raise InputError(f"{label}: cannot write into {folder} ({exc.strerror or exc})") from None


def prepare_output_dir(out: Path | str, option: str = "--out", force: bool = False,
                       outputs: Collection[str] = ()) -> frozenset[Path]:
    """Make ``out`` ready to take a run's files and return the files it keeps (relative paths: not the run's).

    ``out`` must be new or empty; with ``force`` the files its ``run.yaml`` lists are removed (their folders
    too, once empty) and every other file stays, unless it is, or lies inside, one of ``outputs`` (the names
    this run writes at the top of ``out``). Refusals are one-line ``InputError``s naming ``option``; nothing
    is removed unless the whole folder passes."""
    out = output_path(out, option)
    try:
        if out.exists() and not out.is_dir():
            raise InputError(f"{option} {out}: is a file; expected a new or empty folder")
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{option} {out}: cannot create the folder ({exc.strerror or exc})") from None
    _check_writable_folder(out, f"{option} {out}")
    present = files_under(out)
    if not any(out.iterdir()):
        return frozenset()
    if not force:
        example = sorted(p.name for p in out.iterdir())[0]
        raise InputError(f"{option} {out}: not empty (holds {example}, ...); expected a new or empty folder "
                         f"(--force replaces only the files a previous run listed in its {RUN_FILE})")
    listed = listed_outputs(out) & present
    kept = present - listed
    for path in sorted(kept):
        if path.parts[0] in outputs:
            raise InputError(f"{option} {out}: {path} is in the way of this run's outputs and is not listed in "
                             f"{out / RUN_FILE} as a previous run's; move it or choose another folder")
    folders: set[Path] = set()
    for path in listed:
        (out / path).unlink()
        folders.update(out / parent for parent in path.parents if parent != Path("."))
    for folder in sorted(folders, key=lambda p: len(p.parts), reverse=True):
        if folder.is_dir() and not any(folder.iterdir()):
            folder.rmdir()
    return frozenset(kept)


def record_written(out: Path, kept: Collection[Path], extra: dict | None = None) -> list[str]:
    """List in ``out/run.yaml`` (created if the run wrote none) every file of ``out`` but ``kept`` as this
    run's; ``extra`` keys are added too (e.g. why a run stopped). Returns the list."""
    info = read_run_file(out)
    info.update(extra or {})
    run_file = Path(RUN_FILE)
    written = sorted(str(p) for p in (files_under(out) | {run_file}) - set(kept))
    info[WRITTEN_KEY] = written
    (out / RUN_FILE).write_text(yaml.safe_dump(info, sort_keys=False))
    return written


def check_may_write(folder: Path, names: Iterable[str]) -> None:
    """Each of ``names`` (files in ``folder``, a run's folder) is new or listed in its run.yaml as the run's."""
    listed = listed_outputs(folder)
    for name in names:
        if (folder / name).exists() and Path(name) not in listed:
            raise InputError(f"{folder / name}: exists and is not listed in {folder / RUN_FILE} as the run's own; "
                             "move it away first")


def add_written(folder: Path, names: Iterable[str]) -> None:
    """Add ``names`` (files now written in ``folder``) to its run.yaml's list (a run.yaml made for it, and
    listed, when the folder has none), so that the command may replace them when it runs again."""
    new = [] if (folder / RUN_FILE).is_file() else [RUN_FILE]
    info = read_run_file(folder)
    written = set(str(p) for p in listed_outputs(folder)) | {str(Path(n)) for n in [*names, *new]}
    info[WRITTEN_KEY] = sorted(written)
    (folder / RUN_FILE).write_text(yaml.safe_dump(info, sort_keys=False))


def check_new_path(path: Path | str, option: str, force: bool | None = False, what: str = "file") -> Path:
    """An output path (a file, or a folder a writer creates, e.g. a bag): not blank, in an existing writable
    folder, and new unless ``force`` (None: the command has no --force). ``what`` names it in the errors."""
    path = output_path(path, option)
    try:
        if path.is_dir() and what == "file":
            raise InputError(f"{option} {path}: is a folder; expected a file path")
        if path.exists() and not force:
            raise InputError(f"{option} {path}: exists already; expected a new {what}" + (
                " (or --force to replace it)" if force is not None else ""))
        parent = path.parent
        if not parent.is_dir():
            raise InputError(f"{option} {path}: no folder {parent}")
    except OSError as exc:
        raise InputError(f"{option} {path}: not a usable path ({exc.strerror or exc})") from None
    _check_writable_folder(parent, f"{option} {path}")
    return path
