"""`awalker fitbody DIR` writes body_fitted.yaml and start_fitted.yaml by outdir's rule (issue 57): listed in the
run's run.yaml, and never over a file the run did not write. The fit itself is replaced by a stand-in (it is
tested in test_track_pipeline.py and inference tests); the folder is a faked run."""
from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import pytest
import yaml

from awalker_tools import cli, fit_body
from awalker_tools.outdir import listed_outputs
from awalker_tracker.inference import bodyfit
from awalker_tracker.model.body import BodyDescription
from awalker_tracker.vision.camera import Camera, save_calibration

START_WITHOUT_LEG = "start: {frame: 0, position: [0.0, 0.0], heading: 0.0, speed: 1.3, step_length: 0.7}\n"
FITBODY = ["fitbody", "--factors", "0.95", "1.05", "--frames", "5", "--particles", "10"]


@pytest.fixture
def fits() -> list[str]:
    """The fits made ("legs", "stance"), by the stand-ins of ``run_dir``."""
    return []


@pytest.fixture
def run_dir(tmp_path: Path, monkeypatch, fits: list[str]) -> Path:
    """A tracking run's folder (run.yaml listing its files, calibration, start without a stance leg, body) whose
    recorded features and fits are stand-ins (each fit made is appended to ``fits``)."""
    run = tmp_path / "run"
    run.mkdir()
    save_calibration([Camera.look_at("cam0", 64, 48, 40.0, [5.0, 0.0, 1.5], [0.0, 0.0, 1.0])], run / "calibration.yaml")
    (run / "start.yaml").write_text(START_WITHOUT_LEG)
    (run / "body.yaml").write_text(BodyDescription.default().to_yaml_text())
    (run / "run.yaml").write_text(yaml.safe_dump({"written": ["body.yaml", "calibration.yaml", "run.yaml",
                                                              "start.yaml"]}))
    monkeypatch.setattr(fit_body, "_features", lambda *a: ([i * 33_333_333 for i in range(10)], [[] for _ in range(10)]))

    def leg_fit(body, *a, **k):
        fits.append("legs")
        return SimpleNamespace(body=body, factor=1.05, log_evidence={0.95: -2.0, 1.05: -1.0})

    def stance_fit(*a, **k):
        fits.append("stance")
        return SimpleNamespace(leg=0, log_evidence={0: -1.0, 1: -3.0}, filters=1)

    monkeypatch.setattr(bodyfit, "fit_leg_length", leg_fit)
    monkeypatch.setattr(bodyfit, "fit_stance_leg", stance_fit)
    return run


def test_fitbody_lists_its_files_and_may_replace_them(run_dir: Path, fits: list[str], capsys) -> None:
    assert cli.main([*FITBODY, str(run_dir)]) == 0, capsys.readouterr().err
    assert fits == ["legs", "stance"]
    listed = listed_outputs(run_dir)
    assert {Path("body_fitted.yaml"), Path("start_fitted.yaml")} <= listed
    assert {Path("body.yaml"), Path("run.yaml")} <= listed          # the run's own list kept
    assert (run_dir / "body_fitted.yaml").is_file() and (run_dir / "start_fitted.yaml").is_file()
    assert cli.main([*FITBODY, str(run_dir)]) == 0                  # its own files, written again
    assert fits == ["legs", "stance"] * 2


@pytest.mark.parametrize("name", ["body_fitted.yaml", "start_fitted.yaml"])
def test_fitbody_never_writes_over_a_file_the_run_did_not_write(name: str, run_dir: Path, fits: list[str],
                                                                capsys) -> None:
    (run_dir / name).write_text("mine\n")
    assert cli.main([*FITBODY, str(run_dir)]) == 2
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert lines == [f"awalker fitbody: error: {run_dir / name}: exists and is not listed in {run_dir / 'run.yaml'} "
                     "as the run's own; move it away first"], lines
    assert (run_dir / name).read_text() == "mine\n"
    assert fits == []        # refused before the fit
    assert not ({"body_fitted.yaml", "start_fitted.yaml"} - {name}) & {p.name for p in run_dir.iterdir()}
