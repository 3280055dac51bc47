"""benchmarks/bench_realwalks.py's paired comparison against an earlier report (``--against``), the locks that let
several benchmark processes share one --out, and where a run's start lies along the camera's view."""
from __future__ import annotations

import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

import bench_realwalks  # noqa: E402


def _runs(errors: dict[str, dict[str, float]]) -> dict[str, dict[str, dict]]:
    return {key: {variant: {"absolute_median_mm": mm} for variant, mm in by_variant.items()}
            for key, by_variant in errors.items()}


def test_each_run_is_paired_with_the_same_run_of_the_baseline() -> None:
    baseline = _runs({"07_01 s0": {"two": 50.0, "mono": 100.0}, "07_01 s1": {"two": 60.0, "mono": 90.0},
                      "91_10 s0": {"two": 70.0}, "91_10 s1": {"two": 80.0}})
    report = _runs({"07_01 s0": {"two": 50.5, "mono": 130.0}, "07_01 s1": {"two": 57.0, "mono": 70.0},
                    "91_10 s0": {"two": math.inf}, "91_10 s1": {"two": 100.0},
                    "69_01 s0": {"two": 10.0}})          # not in the baseline: not paired
    baseline["91_36 s0"] = report["91_36 s0"] = {"two": {"absolute_median_mm": math.inf}}   # failed both times
    result = bench_realwalks.paired(report, baseline)
    two, mono = result["two"], result["mono"]
    assert two["runs"] == 5 and mono["runs"] == 2
    # two: +0.5, -3, inf (failed here only), +20, and 0 where it failed both times; the mean and its standard
    # error over the finite ones
    finite = [0.5, -3.0, 20.0, 0.0]
    mean = sum(finite) / 4
    sd = math.sqrt(sum((d - mean) ** 2 for d in finite) / 3)
    assert two["mean_mm"] == pytest.approx(round(mean, 1))
    assert two["standard_error_mm"] == pytest.approx(round(sd / math.sqrt(4), 1))
    assert (two["better"], two["worse"], two["not_finite"]) == (1, 2, 1)     # +0.5 is within the margin
    assert two["median_mm"] == pytest.approx(0.5)
    assert len(two["largest"]) == 4                  # the unchanged run is no change
    assert two["largest"][0] == "91_10 s0 70 -> inf" and two["largest"][1] == "91_10 s1 80 -> 100"
    assert mono["mean_mm"] == pytest.approx(5.0) and (mono["better"], mono["worse"]) == (1, 1)
    assert mono["standard_error_mm"] == pytest.approx(25.0)
    assert bench_realwalks.paired(report, {}) == {}


@pytest.mark.parametrize("content", ["not json", json.dumps({"benchmark": "realwalks"}), json.dumps({"runs": [1]}),
                                     json.dumps({"runs": {"07_01 s0": {"two": {"swap_fraction": 0.0}}}}),
                                     json.dumps({"runs": {"07_01 s0": [50.0]}})])
def test_against_a_file_that_is_not_a_report_is_refused_by_name(tmp_path: Path, capsys, content: str) -> None:
    bad = tmp_path / "old.json"
    bad.write_text(content)
    with pytest.raises(SystemExit) as stop:
        bench_realwalks.main(["--against", str(bad), "--out", str(tmp_path / "out")])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert f"--against {bad}" in err and "not a report of this benchmark" in err
    assert not (tmp_path / "out").exists()          # refused before anything was rendered or tracked
    with pytest.raises(SystemExit):
        bench_realwalks.main(["--against", str(tmp_path / "missing.json"), "--out", str(tmp_path / "out")])
    assert "missing.json" in capsys.readouterr().err


def test_a_run_another_live_process_is_making_is_waited_for_not_deleted(tmp_path: Path) -> None:
    """Two benchmark processes sharing --out: the second waits while the first holds a run's lock, then finds the
    finished run; the lock is gone once its holder leaves, also after an error."""
    import subprocess
    import threading

    run_dir = tmp_path / "runs" / "07_01_s0_two"
    lock = tmp_path / "runs" / "07_01_s0_two.lock"
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        lock.parent.mkdir(parents=True)
        lock.write_text(str(other.pid))
        run_dir.mkdir()                                  # being tracked: no eval.json yet

        def finish() -> None:                            # the other process evaluates the run and lets go
            time.sleep(0.3)
            (run_dir / "eval.json").write_text("{}")
            lock.unlink()

        threading.Thread(target=finish).start()
        started = time.monotonic()
        with bench_realwalks.claimed(run_dir, poll_s=0.05):
            assert time.monotonic() - started >= 0.25
            assert (run_dir / "eval.json").exists()      # found finished, not deleted as a stopped run's
            assert lock.read_text() == str(os.getpid())
    finally:
        other.kill()
        other.wait()
    assert not lock.exists()
    with pytest.raises(RuntimeError):
        with bench_realwalks.claimed(run_dir, poll_s=0.05):
            raise RuntimeError("tracking failed")
    assert not lock.exists()


def test_a_lock_left_by_a_process_that_died_is_taken_over(tmp_path: Path) -> None:
    import subprocess

    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    sequence = tmp_path / "sequences" / "07_01_s0"
    lock = tmp_path / "sequences" / "07_01_s0.lock"
    lock.parent.mkdir(parents=True)
    lock.write_text(str(gone.pid))
    started = time.monotonic()
    with bench_realwalks.claimed(sequence, poll_s=5.0):
        assert lock.read_text() == str(os.getpid())
    assert time.monotonic() - started < 1.0 and not lock.exists()


def test_a_lock_appears_with_its_pid_already_in_it(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The lock comes into being whole (a process killed between creating it and writing its pid would leave an
    empty lock that every other process waits on for ever), and the file it is made from does not stay behind."""
    linked = []
    real_link = os.link

    def watching_link(source, target) -> None:
        linked.append(Path(source).read_text())
        real_link(source, target)

    monkeypatch.setattr(bench_realwalks.os, "link", watching_link)
    run_dir = tmp_path / "runs" / "07_01_s0_two"
    with bench_realwalks.claimed(run_dir, poll_s=0.05):
        assert [p.name for p in (tmp_path / "runs").iterdir()] == ["07_01_s0_two.lock"]
    assert linked == [str(os.getpid())]
    with pytest.raises(RuntimeError):
        with bench_realwalks.claimed(run_dir, poll_s=0.05):
            raise RuntimeError("tracking failed")
    assert list((tmp_path / "runs").iterdir()) == []


def test_a_sequences_folder_linked_to_one_not_made_yet_is_made(tmp_path: Path) -> None:
    """A variant's ``--out`` may link its sequences folder to the default's before the default's benchmark has made
    it; the first lock made there makes the folder the link points to (mkdir on the link itself refused: it exists
    as a link)."""
    target = tmp_path / "default" / "sequences"
    (tmp_path / "variant").mkdir()
    (tmp_path / "variant" / "sequences").symlink_to(target)
    with bench_realwalks.claimed(tmp_path / "variant" / "sequences" / "07_01_s0", poll_s=0.05):
        assert (target / "07_01_s0.lock").read_text() == str(os.getpid())
    assert target.is_dir() and not (target / "07_01_s0.lock").exists()


def test_the_start_is_scored_along_the_first_cameras_line_of_sight(tmp_path: Path) -> None:
    """A start 0.3 m beyond the true pelvis along the first camera's horizontal line of sight and 0.2 m across it
    scores +0.3 m (+ = farther from the camera), whatever the second camera; a start nearer the camera scores < 0;
    no start, or a start at a frame the truth lacks, scores None."""
    from awalker_tools.evaluation import PoseTrack, write_poses_csv
    from awalker_tracker.vision.camera import Camera, save_calibration

    first = Camera.look_at("cam0", 640, 480, 500.0, np.array([0.0, -5.0, 2.0]), np.array([1.0, 0.0, 0.9]))
    second = Camera.look_at("cam1", 640, 480, 500.0, np.array([6.0, 0.0, 2.0]), np.array([1.0, 0.0, 0.9]))
    save_calibration([first, second], tmp_path / "calibration.yaml")
    pelvis = np.array([[1.0 + 0.04 * f, 0.0, 0.95] for f in range(10)])
    truth = tmp_path / "ground_truth.csv"
    write_poses_csv(truth, PoseTrack(np.arange(10), 1_000_000 * np.arange(10), ("pelvis",), pelvis[:, None, :]))
    assert bench_realwalks.start_figures(tmp_path, truth)["start_depth_m"] is None    # no start.yaml
    at = pelvis[4, :2]
    along = (at - first.position[:2]) / np.linalg.norm(at - first.position[:2])
    across = np.array([-along[1], along[0]])

    def scored(position: np.ndarray, frame: int = 4) -> float | None:
        (tmp_path / "start.yaml").write_text(yaml.safe_dump(
            {"start": {"frame": frame, "position": [float(v) for v in position], "heading": 0.0, "speed": 1.0}}))
        return bench_realwalks.start_figures(tmp_path, truth)["start_depth_m"]

    assert scored(at + 0.3 * along + 0.2 * across) == pytest.approx(0.3, abs=1e-3)
    assert scored(at - 0.25 * along) == pytest.approx(-0.25, abs=1e-3)
    assert scored(at, frame=40) is None
