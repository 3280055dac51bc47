"""Console scripts of the nodes: bad parameters give one line naming the program and exit status 2."""
from __future__ import annotations

import os
import subprocess
import sys

import pytest


@pytest.mark.parametrize("module, program, expected", [
    ("awalker_tracker.nodes.tracker_node", "awalker_tracker_node", "parameter 'cameras' is required"),
    ("awalker_tools.replay", "awalker_replay", "parameter 'bag' is required"),
])
def test_node_console_script_rejects_missing_parameters(module: str, program: str, expected: str,
                                                        ros_domain_id: int) -> None:
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="OFF", ROS_DOMAIN_ID=str(ros_domain_id))
    done = subprocess.run([sys.executable, "-c", f"import sys; from {module} import main; sys.exit(main())"],
                          capture_output=True, text=True, env=env, timeout=60, check=False)
    assert done.returncode == 2, done.stderr
    lines = [line for line in done.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith(f"{program}: error: ") and expected in lines[0], done.stderr
    assert "Traceback" not in done.stderr
