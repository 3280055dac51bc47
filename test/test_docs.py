"""The documentation against the code: every setting is in docs/configuration.md, every README command parses
and the quick ones run.

- Each field of the config dataclasses listed below must appear, in backticks, in its own section of
  docs/configuration.md (the ``###`` section whose heading names the class); each module constant listed must
  exist and appear there too. A field added without documentation fails here.
- Each shell command in README.md's code blocks (fenced ``bash``/``sh``/unlabelled blocks and indented blocks)
  and in its inline code spans is checked: an ``awalker ...`` line is parsed by the command's own argparse
  parser (a synopsis with ``[optional]`` parts or ``a|b`` alternatives: its subcommand and every ``--option``
  must exist); a ``python benchmarks/X.py`` line needs the script; a ``make X`` line needs the target.
- Each command of the code blocks is run or listed as parse-only, with the reason, in
  ``scripts/check_readme.py``; the quick ones run here end to end in a temporary folder (the script runs the
  slower ones too).
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import importlib
import io
import os
import re
import shlex
import sys
from pathlib import Path

import pytest

from awalker_tools.cli import build_parser

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT / "scripts"))
from check_readme import classification_errors, commands_of, readme_commands, run_checks, shell_blocks  # noqa: E402
README = REPO_ROOT / "README.md"
CONFIGURATION = REPO_ROOT / "docs" / "configuration.md"

#: The dataclasses whose fields a person may tune: (module, class).
CONFIG_DATACLASSES = (
    ("awalker_tracker.inference.filter_model", "TrackerConfig"),
    ("awalker_tracker.inference.filter_model", "InitialSpread"),
    ("awalker_tracker.inference.smc", "SMCConfig"),
    ("awalker_tracker.inference.profiles", "TrackingProfile"),
    ("awalker_tracker.inference.recovery", "RecoveryConfig"),
    ("awalker_tracker.inference.autostart", "AutoStartConfig"),
    ("awalker_tracker.inference.bodyfit", "BodyFitConfig"),
    ("awalker_tracker.model.walker", "WalkerParams"),
    ("awalker_tracker.model.control", "ControlPrior"),
    ("awalker_tracker.model.kinematics", "KinematicConfig"),
    ("awalker_tracker.model.kinematics", "TurnPrior"),
    ("awalker_tracker.model.kinematics", "JointPrior"),
    ("awalker_tracker.model.body", "BodyDescription"),
    ("awalker_tracker.vision.features", "FeatureConfig"),
    ("awalker_tracker.vision.flow", "FlowConfig"),
    ("awalker_tracker.vision.likelihood", "LikelihoodConfig"),
    ("awalker_tools.replay", "ReplayConfig"),
    ("awalker_tools.pipeline", "TrackOptions"),
    ("awalker_tools.synth", "SynthConfig"),
)

#: Module constants a person may tune, as docs/configuration.md names them (module path after the package).
MODULE_CONSTANTS = (
    "model.dynamics.MAX_STANCE_LEAN", "model.dynamics.MAX_STRIKE_INTERVAL", "model.dynamics.DEFAULT_MAX_SUBSTEP",
    "model.cyclic_gaits.SOLVER_STEP", "model.cyclic_gaits.RESIDUAL_TOLERANCE", "model.cyclic_gaits.PREFERRED_STEP_AT_5KMH",
    "model.cyclic_gaits.PREFERRED_STEP_EXPONENT", "model.control.MIN_IMPULSE_MEAN", "model.kinematics.CHORD_LEAN",
    "model.kinematics.POSTURE_LIMIT", "model.kinematics.PELVIS_CEILING_RANGE",
    "inference.speed.SPEED_TIME_CONSTANT_S", "inference.autostart.AUTO_SPREAD",
    "inference.gait_events.SWING_TIME_S", "inference.gait_events.SWING_PER_STEP_TIME",
    "inference.gait_events.LONGEST_STEP_TIME_S", "inference.gait_events.TYPICAL_STEP_TIME_S",
    "inference.filter_model.JUMP_SPREAD_M_S", "inference.filter_model.JUMP_SPREAD_MIN_S",
    "inference.filter_model.MAX_PUBLISHED_SPEED_M_S",
    "vision.features.MULTI_CAMERA_MAP_WIDTH", "vision.features.MAX_PENDING_FLOWS", "vision.features.SCHEDULE_RATE_HZ",
    "vision.foreground.NUM_COMPONENTS", "vision.foreground.OUTLIER_LOG_DENSITY", "vision.flow.STUDENT_T_DOF",
    "vision.densities.SHADOW_DARKEST", "vision.densities.SHADOW_PRIOR", "vision.densities.SHADOW_EDGE_STD",
    "vision.background.DEFAULT_FLOOR_STD", "vision.background.CHI2_5_999", "vision.background.GAIN_STRIDE",
    "awalker_tools.pipeline.FRAMES_AHEAD", "awalker_tools.pipeline.GIL_SWITCH_INTERVAL_S",
    "awalker_tools.pipeline.ACK_TIMEOUT_S", "awalker_tools.pipeline.RECORD_WAIT_S", "awalker_tools.pipeline.UNDECODABLE_STOP",
    "awalker_tools.pipeline.FIRST_PASS_PARTICLES", "awalker_tools.pipeline.FIT_FRAMES",
    "nodes.pose_publisher_node.DEFAULT_CLOUD_POINTS", "nodes.pose_publisher_node.CONTACT_MIN_PROBABILITY",
    "inference.smc.MAX_PARTICLES", "inference.filter_model.START_MAX_SPEED", "model.body.BODY_LEG_RANGE",
    "awalker_tools.synth.MAX_IMAGE_SIDE", "awalker_tools.commands.gaits.MAX_GRID_POINTS",
    "awalker_tools.video_to_bag.FPS_RANGE", "awalker_tools.video_to_bag.UNREADABLE_RUN_STOP",
)


# ----------------------------------------------------------------------------- configuration.md


def _sections(text: str) -> dict[str, str]:
    """``###`` heading -> its text up to the next heading of level 2 or 3."""
    out: dict[str, str] = {}
    parts = re.split(r"^(#{2,3} .*)$", text, flags=re.MULTILINE)
    for heading, body in zip(parts[1::2], parts[2::2]):
        if heading.startswith("### "):
            out[heading] = body
    return out


def _section_of(class_name: str, sections: dict[str, str]) -> str:
    found = [body for heading, body in sections.items() if f"`{class_name}`" in heading]
    assert len(found) == 1, f"docs/configuration.md: expected one ### section naming `{class_name}`, found {len(found)}"
    return found[0]


@pytest.mark.parametrize(("module", "name"), CONFIG_DATACLASSES, ids=[n for _, n in CONFIG_DATACLASSES])
def test_every_config_field_is_documented(module: str, name: str) -> None:
    cls = getattr(importlib.import_module(module), name)
    assert dataclasses.is_dataclass(cls)
    section = _section_of(name, _sections(CONFIGURATION.read_text()))
    missing = [f.name for f in dataclasses.fields(cls) if f"`{f.name}`" not in section]
    assert not missing, f"docs/configuration.md, section of `{name}`: fields not documented: {missing}"


def test_every_listed_constant_exists_and_is_documented() -> None:
    section = _sections(CONFIGURATION.read_text())["### Module constants"]
    for dotted in MODULE_CONSTANTS:
        module, _, constant = dotted.rpartition(".")
        package = "awalker_tools" if module.startswith("awalker_tools") else "awalker_tracker"
        qualified = module if module.startswith("awalker_tools") else f"{package}.{module}"
        assert hasattr(importlib.import_module(qualified), constant), f"{qualified}.{constant} does not exist"
        assert f"`{dotted}`" in section, f"docs/configuration.md, Module constants: `{dotted}` not documented"


def test_the_section_check_finds_an_undocumented_field() -> None:
    @dataclasses.dataclass(frozen=True)
    class Probe:
        lookahead: int = 3
        not_a_documented_setting: float = 0.0

    section = _section_of("SMCConfig", _sections(CONFIGURATION.read_text()))
    missing = [f.name for f in dataclasses.fields(Probe) if f"`{f.name}`" not in section]
    assert missing == ["not_a_documented_setting"]


# ----------------------------------------------------------------------------- README commands

def inline_commands(text: str) -> list[str]:
    """Inline code spans outside code blocks that start like a command (awalker, python, make)."""
    outside = re.sub(r"^\s*(`{3,}|~{3,}).*?^\s*\1", "", text, flags=re.MULTILINE | re.DOTALL)
    spans = re.findall(r"(?<!`)`([^`\n]+)`(?!`)", outside)
    starts = ("awalker ", ".venv/bin/awalker ", "python ", ".venv/bin/python ", "make ")
    return [s.strip() for s in spans if s.strip().startswith(starts)]


def _tokens(command: str) -> list[str]:
    return shlex.split(command, comments=True)


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _option_strings(parser: argparse.ArgumentParser) -> set[str]:
    return {s for action in parser._actions for s in action.option_strings}


def check_awalker(args: list[str], synopsis: bool) -> str | None:
    """None if ``awalker ARGS`` parses (a synopsis: if its subcommands and options exist), else why not."""
    parser = build_parser()
    if not synopsis:
        err = io.StringIO()
        try:
            with contextlib.redirect_stderr(err):
                parser.parse_args(args)
        except SystemExit as exc:
            if exc.code not in (0, None):
                return err.getvalue().strip().splitlines()[-1] if err.getvalue().strip() else f"exit {exc.code}"
        return None
    current, rest = parser, list(args)
    while (choices := _subparsers(current)) and rest and not rest[0].startswith("-"):
        if rest[0] not in choices:
            return f"no subcommand {rest[0]!r} (there are {sorted(choices)})"
        current, rest = choices[rest[0]], rest[1:]
    if _subparsers(current) and not any(t in _option_strings(current) for t in rest):   # `awalker --version`
        return "a subcommand is missing"
    known = _option_strings(current)
    unknown = [t.split("=")[0] for t in rest if t.startswith("-") and t.split("=")[0] not in known]
    return f"{current.prog}: no option {unknown}" if unknown else None


def _make_targets() -> set[str]:
    text = (REPO_ROOT / "Makefile").read_text()
    return {t for line in re.findall(r"^([\w .-]+):(?!=)", text, flags=re.MULTILINE) for t in line.split()}


def check_command(command: str, names_only: bool = False) -> str | None:
    """None if the command is one this test can vouch for or does not check; else what is wrong. A synopsis, or
    with ``names_only`` (a command named in prose, its arguments left out): only the names are checked."""
    synopsis = names_only or bool(re.search(r"[\[\]|]", command))
    tokens = _tokens(re.sub(r"[\[\]]", " ", command)) if synopsis else _tokens(command)
    if not tokens:
        return None
    program, args = tokens[0], tokens[1:]
    if program in ("awalker", ".venv/bin/awalker"):
        return check_awalker([t for t in args if t != "|"], synopsis)
    if Path(program).name.startswith("python") and args:
        script = args[0]
        if script.endswith(".py") and "NAME" not in script and not (REPO_ROOT / script).is_file():
            return f"no script {script}"
        return None
    if program == "make":
        targets = [t for t in args if "=" not in t and not t.startswith("-")]
        missing = [t for t in targets if t not in _make_targets()]
        return f"no make target {missing}" if missing else None
    return None


def test_readme_code_blocks_parse() -> None:
    text = README.read_text()
    commands = [c for block in shell_blocks(text) for c in commands_of(block)]
    assert sum(c.startswith("awalker ") for c in commands) >= 20, "the README's code blocks were not found"
    failures = [f"{c}\n    -> {why}" for c in commands if (why := check_command(c)) is not None]
    assert not failures, "README.md commands that do not parse:\n" + "\n".join(failures)


def test_readme_names_existing_subcommands_and_options() -> None:
    """Commands named in the README's prose (`awalker track --fit-body`): subcommands and options exist."""
    commands = inline_commands(README.read_text())
    assert commands, "no inline commands found"
    failures = [f"{c}\n    -> {why}" for c in commands if (why := check_command(c, names_only=True)) is not None]
    assert not failures, "README.md names commands or options that do not exist:\n" + "\n".join(failures)


@pytest.mark.parametrize(("command", "wrong"), [
    ("awalker track walk.bag --out run/ --no-such-option", True),
    ("awalker trak walk.bag --out run/", True),
    ("awalker track walk.bag --out run/ [--no-such-option N]", True),
    ("awalker gaits solve --out t.json [--family symmetric|stable]", False),
    ("awalker gaits slove --out t.json [--family symmetric|stable]", True),
    ("awalker track walk.bag --out run/ --particles 5000", False),
    ("awalker track walk.bag --out run/ --particles many", True),
    (".venv/bin/python benchmarks/bench_tracker.py --particles 500", False),
    (".venv/bin/python benchmarks/bench_nothing.py", True),
    ("make test TEST_WORKERS=4", False),
    ("make tests", True),
    ("awalker --version", False),
    ("awalker --verzion", True),
])
def test_the_command_check_tells_right_from_wrong(command: str, wrong: bool) -> None:
    assert (check_command(command) is not None) == wrong


def test_code_blocks_are_found() -> None:
    text = ("Para\n\n```bash\nawalker info a.bag   # comment\nawalker track a.bag \\\n    --out r/\n```\n"
            "```yaml\nawalker: no\n```\n\nText:\n\n    make demo\n\n- item\n\n    not code\n")
    commands = [c for block in shell_blocks(text) for c in commands_of(block)]
    assert commands == ["awalker info a.bag   # comment", "awalker track a.bag  --out r/", "make demo"]


def test_every_readme_command_is_run_or_parse_only() -> None:
    """scripts/check_readme.py classifies every command of the README's code blocks, and only those."""
    errors = classification_errors(readme_commands())
    assert not errors, "\n".join(errors)


@pytest.mark.slow
def test_readme_quick_commands_run(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The README's quick commands (info, report, eval, simulate, gaits plot, --help, --version; report and eval
    on a run of the sample bag at 500 particles) run end to end and write what they say: under a minute."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
    monkeypatch.setenv("ROS_DOMAIN_ID", str(90 + int(worker.removeprefix("gw") or 0)))
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "OFF")
    results = run_checks(quick_only=True, root=tmp_path, jobs=2, report=lambda line: None)
    assert len(results) >= 10, [r.line for r in results]
    failures = [f"{r.line or r.command}: {r.why}" for r in results if not r.ok]
    assert not failures, "\n\n".join(failures)
