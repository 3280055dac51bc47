"""`awalker track` stopped by SIGTERM or SIGINT (issue 57): it stops within seconds, writes poses.csv, summary.csv
and gait.csv for the frames done, closes result.bag readable, marks run.yaml incomplete and exits 128 + the
signal's number; `awalker eval` and `awalker report` say the folder is incomplete and work on what it holds."""
from __future__ import annotations

import re
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest
import yaml
from bag_helpers import isolated_ros, synth_walk  # noqa: F401 (isolated_ros: an autouse fixture)

from awalker_tools import evaluation
from awalker_tools.cli import main

FRAMES, BACKGROUND = 150, 4
# Enough particles that the 150 frames take ~15 s on a quiet machine (5 s at 5000): at 50 the whole run streamed in
# 1.5 s, before its first progress line (every 2 s), and ended before the test could interrupt it.
INTERRUPTED_PARTICLES = 15000
# Posteriors the progress line must count before the signal: the synthetic walker enters the picture at its left
# edge and is in view (inference.visibility) from about its 7th frame, and `awalker eval` scores frames in view
# only; signalled at the first progress line, a run once held 4 posteriors, none in view, and eval had nothing to
# score.
POSTERIORS_BEFORE_SIGNAL = 15



@pytest.fixture(scope="module")
def long_bag(tmp_path_factory) -> Path:
    """A 160x120 one-camera synthetic walk of 150 frames with the person (5 s): long enough to interrupt."""
    return synth_walk(tmp_path_factory, FRAMES, BACKGROUND)


def _tracked_enough(line: str) -> bool:
    """A progress line counting at least ``POSTERIORS_BEFORE_SIGNAL`` posteriors."""
    done = re.search(r"frame \d+/\d+, (\d+) posteriors", line)
    return done is not None and int(done.group(1)) >= POSTERIORS_BEFORE_SIGNAL


def _interrupt(bag: Path, out: Path, signum: int,
               options: tuple[str, ...] = ("--particles", str(INTERRUPTED_PARTICLES)),
               ready: Callable[[str], bool] = _tracked_enough) -> tuple[int, str, float]:
    """Run `awalker track` on ``bag`` with ``options``, send ``signum`` once a line of its stderr is ``ready``
    (by default: the progress line counts ``POSTERIORS_BEFORE_SIGNAL`` posteriors); returns (exit status, stderr,
    seconds from the signal to the exit)."""
    proc = subprocess.Popen([sys.executable, "-m", "awalker_tools.cli", "track", str(bag), "--out", str(out), *options],
                            stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True)
    lines = []
    try:
        for line in proc.stderr:
            lines.append(line)
            if ready(line):
                break
        else:
            pytest.fail("awalker track ended before it was interrupted:\n" + "".join(lines))
        proc.send_signal(signum)
        sent = time.monotonic()
        rest = proc.communicate(timeout=120)[1]
        return proc.returncode, "".join(lines) + rest, time.monotonic() - sent
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_an_interrupted_run_writes_what_it_tracked(long_bag: Path, tmp_path: Path, signum: int, capsys):
    from rosbags.rosbag2 import Reader

    out = tmp_path / "run"
    status, err, seconds = _interrupt(long_bag, out, signum)
    name = signal.Signals(signum).name
    assert status == 128 + signum, err
    assert seconds < 10, seconds          # the frame in work, the look-ahead's last frames, the CSV files
    assert "Traceback" not in err
    last = err.strip().splitlines()[-1]
    assert last.startswith(f"awalker track: interrupted by {name} at frame ") and "poses.csv" in last, last
    poses = evaluation.read_poses_csv(out / "poses.csv")
    summary = evaluation.read_summary_csv(out / "summary.csv")
    tracked = len(poses.frames)
    assert 0 < tracked < FRAMES and len(summary["frame"]) == tracked
    assert poses.frames.tolist() == list(range(BACKGROUND, BACKGROUND + tracked))
    assert (out / "gait.csv").read_text().startswith("track,index,frame,stamp_ns")
    with Reader(out / "result.bag") as reader:            # metadata written: the bag opens and reads
        posteriors = [c for c in reader.connections if c.topic == "/awalker/posterior"]
        assert posteriors and sum(1 for _ in reader.messages(connections=posteriors)) == tracked
    run = yaml.safe_load((out / "run.yaml").read_text())
    assert re.fullmatch(rf"interrupted by {name} at frame \d+ of {FRAMES + BACKGROUND}; poses.csv, summary.csv and "
                        rf"gait.csv hold the {tracked} frames tracked", run["incomplete"]), run["incomplete"]
    assert run["posteriors"] == tracked and {"poses.csv", "result.bag/metadata.yaml"} <= set(run["written"])
    if signum == signal.SIGTERM:
        # eval and report say so in one line, and work on what the folder holds
        assert main(["eval", str(out)]) == 0
        err = capsys.readouterr().err.strip().splitlines()
        assert err == [f"awalker eval: {out} is incomplete ({run['incomplete']}); evaluating the frames it holds"]
        assert main(["report", str(out)]) == 0
        err = capsys.readouterr().err.strip().splitlines()
        assert err == [f"awalker report: {out} is incomplete ({run['incomplete']}); reporting the frames it holds"]
        assert "Incomplete run:</strong> interrupted by SIGTERM" in (out / "report.html").read_text()


def test_a_signal_during_the_first_pass_fit_stops_the_fit(long_bag: Path, tmp_path: Path):
    """SIGINT while `awalker track --fit-body` weighs its candidate legs: the candidate filters stop at their next
    frame (the fit's check), not after the whole fit; run.yaml says where it stopped."""
    out = tmp_path / "run"
    status, err, _ = _interrupt(long_bag, out, signal.SIGINT, ("--particles", "50", "--fit-body", "--no-overlay"),
                                ready=lambda line: "awalker track: fitting" in line)
    assert status == 128 + signal.SIGINT, err
    assert "during the first pass's fit" in err and "tracking again" not in err, err
    assert "during the first pass's fit" in yaml.safe_load((out / "run.yaml").read_text())["incomplete"]
