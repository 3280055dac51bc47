#!/usr/bin/env python3
"""Run README.md's shell commands end to end, each in a fresh temporary folder, and check they succeed.

Every command of README.md's shell code blocks (fenced ``bash``/``sh``/unlabelled blocks and indented blocks)
is listed in ``PLANS`` with what this script does with it:

- ``quick``: run; finishes in seconds (``test/test_docs.py::test_readme_quick_commands_run`` runs these);
- ``slow``: run; up to a minute or so each (tracking at 15000 particles, synthesis, the demo);
- ``parse``: not run, for the reason given (the user's own videos, a ROS installation, a node that spins
  until stopped, hours of benchmark). ``test/test_docs.py`` still checks every README command: an
  ``awalker`` line parses with the command's own parser, a script or make target it names exists.

A README command missing from ``PLANS``, or a plan whose command left the README, is an error: when the
README changes, classify its commands here. A synopsis (``[optional]`` parts, ``a|b``) runs as the concrete
command lines its plan gives.

Each command runs with the working directory a new folder holding what the README takes to be at hand:
``walk.bag`` with ``start.yaml`` and ``body.yaml`` beside it, ``cal.yaml`` and ``ground_truth.csv`` (the sample
sequence of ``bags/``), a copy of ``bags/``, ``test/data`` (linked, read-only), and for commands that read a
run, ``run/``: the sample bag tracked (with ``--quick`` at 500 particles without overlay, else as the README's
``awalker track walk.bag --out run/``), after ``awalker fitbody run/`` where a command needs
``run/body_fitted.yaml``. ``awalker`` is this environment's (the one next to the Python running this script).
ROS 2 discovery is off (``ROS_AUTOMATIC_DISCOVERY_RANGE=OFF``) unless set: `awalker track` runs its nodes in
one process.

    .venv/bin/python scripts/check_readme.py            # every command that runs (a few minutes on 2 cores)
    .venv/bin/python scripts/check_readme.py --quick    # the quick ones (under a minute)
    .venv/bin/python scripts/check_readme.py --list     # each command and what is done with it

Exit status 0 when every command run exits 0 and writes the files its plan names, 1 otherwise.
"""
from __future__ import annotations

import argparse
import os
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
README = REPO_ROOT / "README.md"

# ----------------------------------------------------------------------------- the README's commands

_FENCE = re.compile(r"^(\s*)(`{3,}|~{3,})\s*([\w+-]*)")
_SHELL_LANGUAGES = {"", "bash", "sh", "shell", "console"}
_LIST_ITEM = re.compile(r"^\s*([-*+]|\d+[.)])\s")


def shell_blocks(text: str) -> list[list[str]]:
    """Lines of the fenced shell blocks (bash, sh, shell, console or unlabelled) and of the indented code
    blocks of a Markdown text (an indented block follows a blank line after a paragraph or heading that is
    not indented and not a list item)."""
    blocks: list[list[str]] = []
    lines = text.splitlines()
    i = 0
    while i < len(lines):
        m = _FENCE.match(lines[i])
        if m:
            fence, language = m.group(2), m.group(3).lower()
            body = []
            i += 1
            while i < len(lines) and not lines[i].strip().startswith(fence):
                body.append(lines[i])
                i += 1
            if language in _SHELL_LANGUAGES:
                blocks.append(body)
            i += 1
            continue
        if (lines[i].startswith("    ") and lines[i].strip() and i >= 2 and not lines[i - 1].strip()
                and lines[i - 2].strip() and not lines[i - 2].startswith(" ") and not _LIST_ITEM.match(lines[i - 2])):
            body = []
            while i < len(lines) and (lines[i].startswith("    ") or not lines[i].strip()):
                body.append(lines[i][4:])
                i += 1
            blocks.append(body)
            continue
        i += 1
    return blocks


def commands_of(lines: list[str]) -> list[str]:
    """The commands of a block's lines: backslash continuations joined, comments and blank lines dropped."""
    out: list[str] = []
    pending = ""
    for line in lines:
        stripped = line.strip()
        if stripped.endswith("\\"):
            pending += stripped[:-1] + " "
            continue
        command = (pending + stripped).strip()
        pending = ""
        if command and not command.startswith("#"):
            out.append(command)
    return out


def normalise(command: str) -> str:
    """A command as ``PLANS`` names it: its words, single-spaced, without the trailing comment."""
    return " ".join(shlex.split(command, comments=True))


def readme_commands(text: str | None = None) -> list[str]:
    """The README's shell commands, normalised, in order, each once."""
    text = README.read_text() if text is None else text
    return list(dict.fromkeys(normalise(c) for block in shell_blocks(text) for c in commands_of(block)))


# ----------------------------------------------------------------------------- what is done with each


@dataclass(frozen=True)
class Plan:
    kind: str                                   # "quick", "slow" or "parse"
    runs: tuple[str, ...] = ()                  # the command lines run (default: the README command itself)
    needs: str | None = None                    # "run": a tracked run/; "fitted": run/ after fitbody
    creates: tuple[str, ...] = ()               # files (relative to the folder) the command must write
    reason: str = ""                            # why a "parse" command is not run


def quick(*runs: str, needs: str | None = None, creates: tuple[str, ...] = ()) -> Plan:
    return Plan("quick", runs, needs, creates)


def slow(*runs: str, needs: str | None = None, creates: tuple[str, ...] = ()) -> Plan:
    return Plan("slow", runs, needs, creates)


def parse(reason: str) -> Plan:
    return Plan("parse", reason=reason)


USER_VIDEO = "needs the user's own videos (walk.mp4, side.mp4) and image folders"
ROS_INSTALL = "needs a ROS 2 Jazzy installation (/opt/ros/jazzy, colcon, ros2)"
LOCKSTEP = "lockstep replay waits for the tracker's acks: it runs with the nodes of the same block"
NODE = "a node that spins until stopped; its --help is run by test/nodes/test_node_help.py"
RUN_FILES = ("run/poses.csv", "run/summary.csv", "run/gait.csv", "run/result.bag", "run/run.yaml")

#: README command (normalised) -> plan. Extra commands the README names in its prose come last.
PLANS: dict[str, Plan] = {
    "make demo": parse("writes demo_out/ into the checkout; `awalker demo --bag walk.bag --out demo_out` below runs the "
                       "same demo"),
    "make test": parse("the test suite itself"),
    "awalker convert --calibration cal.yaml --video cam0=walk.mp4 [--video cam1=side.mp4] --out walk.bag":
        parse(USER_VIDEO),
    "awalker info walk.bag": quick(),
    "awalker track walk.bag --out run/": slow(creates=RUN_FILES + ("run/overlay.mp4",)),
    "awalker report run/": quick(needs="run", creates=("run/report.html",)),
    "awalker eval run/ --truth ground_truth.csv": quick(needs="run", creates=("run/eval.json",)),
    "awalker convert --calibration cal.yaml --out walk.bag --video cam0=walk.mp4 [--video cam1=side.mp4] "
    "[--images cam0=frames/] [--timestamps stamps.txt | --fps 30 [--start-time S]] [--storage mcap|sqlite3] "
    "[--compressed [--image-format png|jpeg]] [--start-description start.yaml] [--body-description body.yaml]":
        parse(USER_VIDEO),
    "awalker info walk.bag [--json]": quick("awalker info walk.bag --json"),
    "awalker replay walk.bag [--rate R] [--lockstep [--ack-topic /awalker/ack] [--ack-timeout 60] [--frames-ahead N]] "
    "[--topics T ...] [--wait-for-subscribers 10]": slow("awalker replay walk.bag"),
    "awalker_replay --ros-args -p bag:=walk.bag -p lockstep:=true": parse(LOCKSTEP),
    "awalker track bags/walk.bag --out run/ [--start start.yaml] [--body body.yaml] [--particles 15000] [--seed 0]":
        slow("awalker track bags/walk.bag --out run/ --start start.yaml --body body.yaml --particles 15000 --seed 0",
             creates=RUN_FILES),
    "awalker track walk.bag --out run/ --auto-start [--follow-near X Y]":
        slow("awalker track walk.bag --out run/ --auto-start", creates=RUN_FILES + ("run/start.yaml",)),
    "awalker track walk.bag --out run/ --fit-body": slow(creates=RUN_FILES),
    "awalker track walk.bag --out run/ --profile realtime --no-overlay": slow(creates=RUN_FILES),
    "awalker fitbody run/ [--factors 0.94 0.97 1.0 1.03] [--frames 60] [--particles 5000] [--seed 0]":
        slow("awalker fitbody run/", needs="run", creates=("run/body_fitted.yaml",)),
    "awalker track walk.bag --out run2/ --body run/body_fitted.yaml":
        slow(needs="fitted", creates=("run2/poses.csv",)),
    "awalker eval run/ [--truth ground_truth.csv | --truth seq.bag] [--json out.json]":
        quick("awalker eval run/ --json out.json", needs="run", creates=("out.json",)),
    "awalker demo [--bag BAG] [--out demo_out] [--force] [--particles 15000] [--seed 0]":
        slow("awalker demo --bag walk.bag --out demo_out", creates=("demo_out/poses.csv", "demo_out/eval.json")),
    "awalker synth --out seq/ --cameras 3 --frames 90 --seed 1": slow(creates=("seq/synth.bag",)),
    "awalker synth --out seq_turn/ --turn 60 --speed-change --occluder": slow(creates=("seq_turn/synth.bag",)),
    "awalker synth --out seq_mocap/ --from-mocap test/data/mocap/cmu_subject07/07.asf "
    "test/data/mocap/cmu_subject07/07_02.amc --person dressed --variant u-turn --frames 132 --user-start "
    "--tape-measure": slow(creates=("seq_mocap/synth.bag",)),
    "awalker synth --out seq_own/ --from-mocap test/data/mocap/cmu_subject07/07.asf "
    "test/data/mocap/cmu_subject07/07_01.amc --person dressed --no-descriptions --background-frames 0":
        slow(creates=("seq_own/synth.bag",)),
    "awalker simulate --speed 1.3 --step-length 0.7 --steps 10 --out walk.csv": quick(creates=("walk.csv",)),
    "awalker simulate --speed 1.3 --step-length 0.7 --stochastic --seed 1 --out walk.json":
        quick(creates=("walk.json",)),
    "awalker simulate --angle 0.4 --stance-rate -1.8 --swing-rate -1.2 --stiffness 0.6 --impulse 0.38 --out x.csv":
        quick(creates=("x.csv",)),
    "awalker gaits solve --out t.json --speeds 2:7:11 --step-lengths 0.3:1.2:19 [--family symmetric|stable]":
        slow("awalker gaits solve --out t.json --speeds 2:7:11 --step-lengths 0.3:1.2:19", creates=("t.json",)),
    "awalker gaits plot --out plots/": quick(),
    ".venv/bin/python benchmarks/bench_realwalks.py --set reporting --seeds 0 1 2 3 4 5 6 7 8 9 --markdown table.md":
        parse("tracks the reporting set: hours on 2 cores"),
    "source /opt/ros/jazzy/setup.bash": parse(ROS_INSTALL),
    "pip install rosbags opencv-python-headless scipy matplotlib": parse(ROS_INSTALL),
    "colcon build --symlink-install": parse(ROS_INSTALL),
    "source install/setup.bash": parse(ROS_INSTALL),
    "ros2 run awalker_tracker awalker_features --ros-args -p camera_name:=cam0": parse(ROS_INSTALL),
    ".venv/bin/awalker_replay --ros-args -p bag:=bags/walk.bag -p lockstep:=true": parse(LOCKSTEP),
    ".venv/lib/awalker_tracker/awalker_features --ros-args -p camera_name:=cam0": parse(NODE),
    ".venv/lib/awalker_tracker/awalker_tracker_node --ros-args -p cameras:=[cam0]": parse(NODE),
    ".venv/lib/awalker_tracker/awalker_pose_publisher": parse(NODE),
}

#: Commands the README names in its prose, not in a code block: run too.
EXTRA: dict[str, Plan] = {
    "awalker --help": quick(),
    "awalker --version": quick(),
}

#: The run/ that commands reading a run get: the sample bag tracked (quick: 500 particles, no overlay).
RUN_FIXTURE = {True: "awalker track walk.bag --out run/ --particles 500 --no-overlay",
               False: "awalker track walk.bag --out run/"}


def classification_errors(commands: list[str]) -> list[str]:
    """What keeps ``PLANS`` from matching the README's commands one to one."""
    missing = [f"not in PLANS (classify it in scripts/check_readme.py): {c}" for c in commands if c not in PLANS]
    stale = [f"in PLANS but no longer in README.md: {c}" for c in PLANS if c not in commands]
    return missing + stale


# ----------------------------------------------------------------------------- running


@dataclass
class Result:
    command: str            # the README's command
    line: str               # the command line run
    ok: bool
    seconds: float
    why: str = ""


@dataclass
class Workspace:
    """Temporary folders under ``root``, each set up with the README's files; a tracked run/ made once."""

    root: Path
    quick: bool
    _lock: threading.Lock = field(default_factory=threading.Lock)           # the folder count
    _fixture_lock: threading.Lock = field(default_factory=threading.Lock)   # making a fixture
    _fixtures: dict[str, Path] = field(default_factory=dict)
    _count: int = 0

    def folder(self, name: str) -> Path:
        with self._lock:
            self._count += 1
            folder = self.root / f"{self._count:02d}_{re.sub(r'[^A-Za-z0-9]+', '_', name)[:40]}"
        folder.mkdir(parents=True)
        sample = REPO_ROOT / "bags"
        for source, target in [("walk.bag", "walk.bag"), ("start.yaml", "start.yaml"), ("body.yaml", "body.yaml"),
                               ("calibration.yaml", "cal.yaml"), ("ground_truth.csv", "ground_truth.csv")]:
            copy = shutil.copytree if (sample / source).is_dir() else shutil.copy2
            copy(sample / source, folder / target)
        shutil.copytree(sample, folder / "bags")
        (folder / "test").mkdir()
        (folder / "test" / "data").symlink_to(REPO_ROOT / "test" / "data")
        return folder

    def fixture(self, name: str) -> Path:
        """The folder holding run/ (``run``) or run/ after ``awalker fitbody run/`` (``fitted``), made once."""
        with self._fixture_lock:
            if name in self._fixtures:
                return self._fixtures[name]
            folder = self.folder(f"fixture_{name}")
            steps = [RUN_FIXTURE[self.quick]] + (["awalker fitbody run/"] if name == "fitted" else [])
            for step in steps:
                code, output = execute(step, folder)
                if code != 0:
                    raise RuntimeError(f"making the {name} fixture: `{step}` exited {code}:\n{output}")
            self._fixtures[name] = folder
            return folder

    def prepared(self, plan: Plan, name: str) -> Path:
        folder = self.folder(name)
        if plan.needs:
            shutil.rmtree(folder / "run", ignore_errors=True)
            shutil.copytree(self.fixture(plan.needs) / "run", folder / "run")
        return folder


def awalker_bin() -> Path:
    return Path(sys.executable).parent


def execute(line: str, cwd: Path, timeout: float = 900.0) -> tuple[int, str]:
    """Run ``line`` (an ``awalker ...`` command; ``.venv/...`` paths are the checkout's) in ``cwd``."""
    words = shlex.split(line)
    if words[0] == "awalker":
        words[0] = str(awalker_bin() / "awalker")
    elif words[0].startswith(".venv/"):
        words[0] = str(REPO_ROOT / words[0])
    env = dict(os.environ)
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "OFF")
    env["PATH"] = f"{awalker_bin()}{os.pathsep}{env.get('PATH', '')}"
    try:
        done = subprocess.run(words, cwd=cwd, env=env, stdin=subprocess.DEVNULL, capture_output=True, text=True,
                              timeout=timeout, check=False)
    except subprocess.TimeoutExpired as exc:
        return 124, f"timed out after {timeout:g} s\n{exc.stdout or ''}{exc.stderr or ''}"
    return done.returncode, done.stdout + done.stderr


def run_one(workspace: Workspace, command: str, plan: Plan, line: str) -> Result:
    start = time.monotonic()
    try:
        folder = workspace.prepared(plan, line)
    except RuntimeError as exc:
        return Result(command, line, False, time.monotonic() - start, str(exc))
    code, output = execute(line, folder)
    missing = [f for f in plan.creates if not (folder / f).exists()]
    seconds = time.monotonic() - start
    if code != 0:
        return Result(command, line, False, seconds, f"exit status {code}:\n{output[-3000:]}")
    if missing:
        return Result(command, line, False, seconds, f"did not write {missing}:\n{output[-3000:]}")
    return Result(command, line, True, seconds)


def selected(quick_only: bool, commands: list[str]) -> list[tuple[str, Plan, str]]:
    """(README command, plan, command line) of every line to run, README order, extras last."""
    out = []
    for command, plan in [(c, PLANS[c]) for c in commands if c in PLANS] + list(EXTRA.items()):
        if plan.kind == "parse" or (quick_only and plan.kind != "quick"):
            continue
        out.extend((command, plan, line) for line in (plan.runs or (command,)))
    return out


def run_checks(quick_only: bool, root: Path, jobs: int = 2, match: str = "",
               report=print) -> list[Result]:
    """Run the selected commands (``jobs`` at a time) in folders under ``root``; their results."""
    commands = readme_commands()
    if errors := classification_errors(commands):
        return [Result(e, "", False, 0.0, "README.md and PLANS disagree") for e in errors]
    todo = [t for t in selected(quick_only, commands) if match in t[2]]
    workspace = Workspace(root, quick_only)

    def one(item: tuple[str, Plan, str]) -> Result:
        result = run_one(workspace, *item)
        report(f"{'ok  ' if result.ok else 'FAIL'} {result.seconds:6.1f} s  {result.line}")
        return result

    with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
        return list(pool.map(one, todo))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="run only the quick commands")
    parser.add_argument("--list", action="store_true", help="list each README command and what is done with it")
    parser.add_argument("--jobs", type=int, default=2, help="commands run at a time (default 2)")
    parser.add_argument("-k", dest="match", default="", help="run only the command lines containing this text")
    parser.add_argument("--keep", type=Path, help="run in this new folder and keep it (default: a temporary one)")
    args = parser.parse_args(argv)

    if args.list:
        commands = readme_commands()
        for command in commands + list(EXTRA):
            plan = PLANS.get(command) or EXTRA.get(command)
            if plan is None:
                print(f"UNCLASSIFIED  {command}")
            elif plan.kind == "parse":
                print(f"parse only    {command}\n              ({plan.reason})")
            else:
                print(f"{plan.kind:<13} {command}")
                for line in plan.runs:
                    print(f"              runs: {line}")
        errors = classification_errors(commands)
        for error in errors:
            print(error, file=sys.stderr)
        return 1 if errors else 0

    started = time.monotonic()
    if args.keep:
        args.keep.mkdir(parents=True)
        results = run_checks(args.quick, args.keep, args.jobs, args.match)
    else:
        with tempfile.TemporaryDirectory(prefix="check_readme_") as tmp:
            results = run_checks(args.quick, Path(tmp), args.jobs, args.match)
    failed = [r for r in results if not r.ok]
    for r in failed:
        print(f"\nFAILED: {r.line or r.command}\n{r.why}", file=sys.stderr)
    print(f"{len(results) - len(failed)} of {len(results)} README commands ran and succeeded "
          f"in {time.monotonic() - started:.0f} s")
    return 1 if failed or not results else 0


if __name__ == "__main__":
    sys.exit(main())
