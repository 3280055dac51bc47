"""Every node executable answers -h/--help with its ROS parameters and defaults, without starting ROS; the
parameters a node declares are the ones its --help lists (one table, ``nodes.base.NodeParameter``); and
`awalker --version` prints the package's version (issue 57)."""
from __future__ import annotations

import importlib
import subprocess
import sys
from importlib.metadata import version

import pytest
from rclpy.parameter import Parameter

from awalker_tools import cli
from awalker_tracker.nodes.base import Default, _shown

NODES = [("awalker_tracker.nodes.tracker_node", "awalker_tracker_node"),
         ("awalker_tracker.nodes.features_node", "awalker_features"),
         ("awalker_tracker.nodes.pose_publisher_node", "awalker_pose_publisher"),
         ("awalker_tools.replay", "awalker_replay")]


def test_every_console_script_of_a_node_is_covered() -> None:
    """The entry points of both packages' setup.py: each node executable is in NODES."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[2] / "src"
    scripts = {}
    for setup in ("awalker_tracker/setup.py", "awalker_tools/setup.py"):
        for line in (root / setup).read_text().splitlines():
            if " = awalker_" in line and ":main" in line:
                name, target = line.strip().strip("',").split(" = ")
                scripts[name] = target.removesuffix(":main")
    scripts.pop("awalker")            # the CLI, not a node
    assert {program: module for module, program in NODES} == scripts


@pytest.mark.parametrize("module, program", NODES)
@pytest.mark.parametrize("flag", ["--help", "-h"])
def test_help_lists_the_parameters_without_starting_ros(module: str, program: str, flag: str, monkeypatch,
                                                        capsys) -> None:
    import rclpy

    monkeypatch.setattr(rclpy, "init", lambda *a, **k: pytest.fail("--help started ROS"))
    node_module = importlib.import_module(module)
    assert node_module.main([flag]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"usage: {program} [--ros-args")
    rows = [line.strip() for line in out.splitlines() if line.startswith("  ")]
    assert len(rows) == len(node_module.PARAMETERS) >= 5
    for row, p in zip(rows, node_module.PARAMETERS):
        assert row.startswith(p.name + " ") and row.endswith(f"({_shown(p.default)})"), row
    # a --help meant for ROS (after --ros-args) is not ours: ROS starts (here: the patched init fails)
    with pytest.raises(pytest.fail.Exception):
        node_module.main(["--ros-args", "--help"])


def test_pose_publisher_console_script_answers_help_at_once() -> None:
    """It answers --help and exits, rather than spinning until killed."""
    done = subprocess.run([sys.executable, "-c", "import sys; from awalker_tracker.nodes.pose_publisher_node import main; "
                           "sys.exit(main())", "--help"], capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 0 and "cloud_points" in done.stdout and not done.stderr, done.stderr


def test_defaults_shown_are_the_declared_ones(ros_context) -> None:
    """Each node declares exactly its table's parameters, with the table's defaults and descriptions."""
    from awalker_tracker.nodes import features_node, pose_publisher_node, tracker_node

    cases = [(pose_publisher_node.PosePublisherNode, pose_publisher_node.PARAMETERS, []),
             (features_node.FeatureNode, features_node.PARAMETERS, [Parameter("camera_name", value="cam0")]),
             (tracker_node.TrackerNode, tracker_node.PARAMETERS, [Parameter("cameras", value=["cam0"])])]
    for cls, table, overrides in cases:
        node = cls(context=ros_context, parameter_overrides=overrides)
        try:
            given = {o.name for o in overrides}
            for p in table:
                assert node.has_parameter(p.name), p.name
                if p.name in given or isinstance(p.default, Parameter.Type):     # given, or unset
                    continue
                value = node.get_parameter(p.name).value
                if isinstance(p.default, Default):
                    assert value == p.default.compute(node.get_parameter(p.default.after).value), p.name
                else:
                    assert value == p.default, p.name
                assert node.describe_parameter(p.name).description == p.description
        finally:
            node.destroy_node()
    node = tracker_node.TrackerNode(context=ros_context, parameter_overrides=[
        Parameter("cameras", value=["cam0"]), Parameter("profile", value="realtime")])
    try:
        assert node.get_parameter("num_particles").value == 5000       # the profile's default, as --help says
    finally:
        node.destroy_node()


def test_awalker_version(capsys) -> None:
    with pytest.raises(SystemExit) as done:
        cli.main(["--version"])
    assert done.value.code == 0
    assert capsys.readouterr().out.strip() == f"awalker {version('awalker_tools')}"
