"""`awalker simulate` and `awalker gaits`: outputs, an independent energy check from the CSV, errors."""
from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from awalker_tools.cli import main

# the documented default walker (README): L = 0.9 m, Kuo's ratios, g = 9.81
L, R, C, M_LEG, M_TORSO, GYR, G = 0.9, 0.27, 0.5805, 0.16, 0.68, 0.326 * 0.9, 9.81


def read_rows(path) -> list[dict]:
    with open(path) as fh:
        return list(csv.DictReader(fh))


def energy_from_row(row: dict) -> float:
    """Kinetic + potential energy per kg, from the CSV angles/rates, by hand (point velocities)."""
    p1, p2 = float(row["stance_angle"]), float(row["swing_angle"])
    w1, w2 = float(row["stance_rate"]), float(row["swing_rate"])
    kappa = float(row["stiffness"])
    foot_v = np.array([-R * w1, 0.0])

    def along_stance(d):  # point at distance d above the stance foot centre
        return np.array([-np.sin(p1), np.cos(p1)]) * d, foot_v + np.array([-np.cos(p1), -np.sin(p1)]) * d * w1

    (st, st_v), (hip, hip_v) = along_stance(C - R), along_stance(L - R)
    sw = hip + (L - C) * np.array([np.sin(p2), -np.cos(p2)])
    sw_v = hip_v + (L - C) * w2 * np.array([np.cos(p2), np.sin(p2)])
    inertia = M_LEG * GYR**2
    kinetic = 0.5 * (M_LEG * st_v @ st_v + M_LEG * sw_v @ sw_v + M_TORSO * hip_v @ hip_v
                     + inertia * (w1**2 + w2**2))
    height = M_LEG * (R + st[1]) + M_LEG * (R + sw[1]) + M_TORSO * (R + hip[1])
    return kinetic + G * height + 0.5 * kappa * (p2 - p1) ** 2


def test_simulate_csv_conserves_energy_between_strikes(tmp_path, capsys) -> None:
    out = tmp_path / "walk.csv"
    assert main(["simulate", "--speed", str(5 / 3.6), "--step-length", "0.7", "--steps", "6", "--out", str(out)]) == 0
    summary = json.loads(capsys.readouterr().out)
    rows = read_rows(out)
    assert list(rows[0]) == ["time", "stance_leg", "stance_angle", "swing_angle", "stance_rate", "swing_rate",
                             "stiffness", "toe_off_impulse", "contact_x", "hip_x", "hip_y", "total_energy",
                             "heel_strike", "fallen"]
    assert summary["heel_strikes"] == 6 and not summary["fallen"]
    assert summary["mean_speed_m_s"] == pytest.approx(5 / 3.6, rel=0.02)
    energy = np.array([energy_from_row(r) for r in rows])
    np.testing.assert_allclose(energy, [float(r["total_energy"]) for r in rows], rtol=1e-9)
    strikes = np.array([int(r["heel_strike"]) for r in rows], bool)
    between = ~strikes[1:]
    drift = np.abs(np.diff(energy))[between]
    assert drift.max() < 1e-6
    # a symmetric cyclic gait: the toe-off gives back exactly what the collision takes
    np.testing.assert_allclose(energy[-1], energy[0], atol=1e-6)
    legs = [r["stance_leg"] for r in rows]
    assert legs[0] == "left" and set(legs) == {"left", "right"}
    contact = np.array([float(r["contact_x"]) for r in rows])
    assert np.all(np.diff(contact)[between] > 0)        # the foot rolls forward as phi1 decreases
    assert np.all(np.diff(contact)[~between] > 0.5)     # new foot ~0.7 m ahead


def test_simulate_stochastic_json_is_seeded(tmp_path, capsys) -> None:
    args = ["simulate", "--speed", "1.2", "--step-length", "0.65", "--steps", "2", "--stochastic"]
    outs = []
    for seed, name in ((7, "a.json"), (7, "b.json"), (8, "c.json")):
        assert main(args + ["--seed", str(seed), "--out", str(tmp_path / name)]) == 0
        outs.append(json.loads((tmp_path / name).read_text()))
    capsys.readouterr()
    assert outs[0]["rows"] == outs[1]["rows"]
    assert outs[0]["rows"] != outs[2]["rows"]
    assert outs[0]["params"]["leg_length"] == 0.9
    stiffness = [r["stiffness"] for r in outs[0]["rows"][1:]]
    assert np.std(np.diff(stiffness)) > 0.005           # kappa_t resampled every frame
    assert main(args + ["--paper-prior", "--out", str(tmp_path / "p.json")]) == 0
    paper = json.loads((tmp_path / "p.json").read_text())["rows"]
    assert np.std([r["stiffness"] for r in paper[1:]]) > 0.3  # the paper's sigma_kappa = 1 per frame
    assert main(["simulate", "--speed", "1.2", "--step-length", "0.65", "--paper-prior",
                 "--out", str(tmp_path / "q.json")]) == 2


def test_simulate_explicit_start(tmp_path, capsys) -> None:
    out = tmp_path / "e.csv"
    assert main(["simulate", "--angle", "0.396", "--stance-rate", "-1.91", "--swing-rate", "-1.30", "--stiffness",
                 "0.737", "--impulse", "0.30", "--steps", "2", "--rate", "60", "--out", str(out)]) == 0
    rows = read_rows(out)
    assert float(rows[1]["time"]) == pytest.approx(1 / 60)
    strikes = np.array([int(r["heel_strike"]) for r in rows[1:]], bool)
    assert strikes.sum() == 2
    steps = np.abs(np.diff([energy_from_row(r) for r in rows]))
    assert steps[~strikes].max() < 1e-6 and steps[strikes].min() > 1e-3   # a weaker push loses energy


@pytest.mark.parametrize("argv, needle", [
    (["--speed", "1.3"], "--step-length"),
    (["--speed", "9", "--step-length", "0.7"], "outside the gait table"),
    (["--angle", "0.3"], "explicit start needs"),
    (["--speed", "1.3", "--step-length", "0.7", "--steps", "0"], "--steps"),
    (["--speed", "1.3", "--step-length", "0.7", "--table", "/nonexistent/t.json"], "/nonexistent/t.json"),
])
def test_simulate_bad_input_exits_2(tmp_path, capsys, argv, needle) -> None:
    assert main(["simulate", "--out", str(tmp_path / "x.csv")] + argv) == 2
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1


def test_gaits_solve_and_plot(tmp_path, capsys) -> None:
    table = tmp_path / "t.json"
    assert main(["gaits", "solve", "--speeds", "4.5:5:2", "--step-lengths", "0.65:0.7:2", "--out", str(table)]) == 0
    captured = capsys.readouterr()
    summary = json.loads(captured.out)
    assert summary["converged"] == 4 and summary["max_residual_converged"] < 1e-8
    assert captured.err.count("[") >= 4                 # one progress line per grid point
    assert main(["gaits", "plot", "--table", str(table), "--out", str(tmp_path / "plots")]) == 0
    for name in ("gait_parameters.png", "impulse_fit.png"):
        assert (tmp_path / "plots" / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main(["gaits", "solve", "--speeds", "5:4", "--out", str(table)]) == 2
    # --family stable keeps the asymmetric gaits at 5 km/h, where the symmetric ones are unstable
    capsys.readouterr()
    assert main(["gaits", "solve", "--speeds", "4.5:5:2", "--step-lengths", "0.65:0.7:2", "--family", "stable",
                 "--out", str(tmp_path / "stable.json")]) == 0
    stable = json.loads(capsys.readouterr().out)
    assert summary["locally_stable_points"] == 2 and stable["locally_stable_points"] == 4


def test_simulate_another_leg_length_walks_the_rescaled_gait(tmp_path, capsys) -> None:
    """--leg-length 0.7: the table (solved for 0.9 m) is rescaled, so the gait is cyclic at the asked speed/step."""
    out = tmp_path / "short.csv"
    assert main(["simulate", "--leg-length", "0.7", "--speed", "1.0", "--step-length", "0.55", "--steps", "6",
                 "--rate", "120", "--out", str(out)]) == 0
    capsys.readouterr()
    rows = read_rows(out)
    strikes = [r for r in rows if r["heel_strike"] == "1"]
    x = np.array([float(r["contact_x"]) for r in strikes])
    t = np.array([float(r["time"]) for r in strikes])
    assert len(strikes) == 6 and rows[-1]["fallen"] == "0"
    np.testing.assert_allclose(np.diff(x), 0.55, atol=0.01)        # steps of the asked length
    np.testing.assert_allclose(np.diff(t), 0.55 / 1.0, atol=1 / 120)  # at the asked speed
