"""Cyclic gaits (eq. 3): solver, packaged table, lookups, bilinear iota fit."""
from __future__ import annotations

import json

import numpy as np
import pytest

from awalker_tracker.errors import InputError
from awalker_tracker.model import dynamics, cyclic_gaits
from awalker_tracker.model.walker import RIGHT, WalkerParams, WalkerState

PARAMS = WalkerParams()


@pytest.fixture(scope="module")
def table() -> cyclic_gaits.GaitTable:
    return cyclic_gaits.GaitTable.load()


def test_double_support_angle_inverts_step_length() -> None:
    s = np.linspace(0.3, 1.3, 21)
    a = cyclic_gaits.double_support_angle(PARAMS, s)
    np.testing.assert_allclose(PARAMS.step_length(a), s, atol=1e-12)


def test_packaged_table_covers_the_grid_with_small_residuals(table: cyclic_gaits.GaitTable) -> None:
    assert table.speeds.size >= 11 and np.sum((table.step_lengths >= 0.5 - 1e-9)) >= 15
    assert table.speeds[0] == pytest.approx(2 / 3.6) and table.speeds[-1] == pytest.approx(7 / 3.6)
    # 0.5-1.2 m asked for; down to 0.3 m so that sampled walkers drifting to short steps stay on the table
    assert table.step_lengths[0] <= 0.5 and table.step_lengths[-1] == pytest.approx(1.2)
    assert table.params == PARAMS
    # the human part of the grid (step ~ 0.65-0.75 m at 5 km/h, growing with speed) is all solved
    human = np.array([[0.4 <= s <= 0.9 for s in table.step_lengths] for _ in table.speeds])
    assert table.converged[human].all()
    assert np.all(table.residual[table.converged] < 1e-8)
    assert len(table.reason) == table.speeds.size and all(len(r) == table.step_lengths.size for r in table.reason)


def test_table_entries_are_cyclic_when_re_simulated(table: cyclic_gaits.GaitTable) -> None:
    """Re-evaluate eq. (3) for a spread of entries, batched, without trusting the stored residual."""
    rng = np.random.default_rng(0)
    idx = [tuple(ij) for ij in np.argwhere(table.converged)]
    picks = [idx[k] for k in rng.choice(len(idx), 6, replace=False)]
    for i, j in picks:
        x = np.array([table.stance_rate[i, j], table.swing_rate[i, j], table.stiffness[i, j],
                      table.toe_off_impulse[i, j]])
        res = cyclic_gaits.cyclic_residual(table.params, table.speeds[i], table.step_lengths[j], x)
        assert np.max(np.abs(res)) < 1e-8


def test_table_gait_walks_at_its_speed_and_step_length_in_frames(table: cyclic_gaits.GaitTable) -> None:
    """Independent of the solver: 30 Hz frames with dynamics.advance reproduce step length and duration."""
    for speed, step in ((4 / 3.6, 0.6), (5 / 3.6, 0.7)):
        w1, w2, kappa, iota = table.lookup(speed, step)
        state = cyclic_gaits.gait_initial_state(PARAMS, speed, step, contact_origin=1.0, stance_leg=RIGHT, table=table)
        assert state.stance_leg[0] == RIGHT
        times, positions, tss = [], [], np.zeros(1)
        for frame in range(150):
            state, ev = dynamics.advance(PARAMS, state, kappa, iota, 1 / 30, time_since_strike=tss)
            tss = ev.time_since_strike
            assert not ev.fallen[0]
            if ev.heel_strike[0]:
                times.append((frame + ev.strike_fraction[0]) / 30)
                positions.append(ev.strike_position[0])
        assert len(times) >= 6
        np.testing.assert_allclose(np.diff(positions), step, atol=2e-3)
        np.testing.assert_allclose(np.diff(times), step / speed, atol=2e-3)
        np.testing.assert_allclose(times[0], step / speed, atol=2e-3)


def test_solver_finds_a_small_grid_from_scratch() -> None:
    params = WalkerParams(leg_length=1.0, gravity=9.8)
    speeds = np.array([4.5, 5.0]) / 3.6
    steps = np.array([0.7, 0.75])
    lines: list[str] = []
    small = cyclic_gaits.solve_grid(params, speeds, steps, progress=lines.append, seed_point=(5 / 3.6, 0.75))
    assert small.converged.all() and len(lines) == 4
    assert np.all(small.residual < 1e-8)
    for i in range(2):
        for j in range(2):
            x = np.array([small.stance_rate[i, j], small.swing_rate[i, j], small.stiffness[i, j],
                          small.toe_off_impulse[i, j]])
            assert np.max(np.abs(cyclic_gaits.cyclic_residual(params, speeds[i], steps[j], x))) < 1e-8
    # a faster gait at the same step length needs a stiffer spring and a bigger push (Fig. 3)
    assert small.stiffness[1, 0] > small.stiffness[0, 0]
    assert small.toe_off_impulse[1, 0] > small.toe_off_impulse[0, 0]


def test_solve_point_reports_failure_instead_of_raising() -> None:
    sol = cyclic_gaits.solve_point(PARAMS, 5 / 3.6, 0.7, np.array([5.0, 5.0, 0.7, 0.4]), max_iterations=3)
    assert not sol.converged and sol.reason


def test_save_load_round_trip_and_lookup_at_nodes(tmp_path, table: cyclic_gaits.GaitTable) -> None:
    path = tmp_path / "t.json"
    table.save(path)
    again = cyclic_gaits.GaitTable.load(path)
    np.testing.assert_array_equal(again.stiffness, table.stiffness)
    np.testing.assert_array_equal(again.converged, table.converged)
    i, j = 4, 6
    w1, w2, k, iota = again.lookup(table.speeds[i], table.step_lengths[j])
    assert (w1, w2, k, iota) == pytest.approx((table.stance_rate[i, j], table.swing_rate[i, j],
                                               table.stiffness[i, j], table.toe_off_impulse[i, j]))
    # midway between two nodes: the average
    mid = 0.5 * (table.speeds[i] + table.speeds[i + 1])
    assert again.lookup(mid, table.step_lengths[j])[2] == pytest.approx(
        0.5 * (table.stiffness[i, j] + table.stiffness[i + 1, j]))


def test_bad_table_files_raise_input_error(tmp_path) -> None:
    missing = tmp_path / "nope.json"
    with pytest.raises(InputError, match="nope.json"):
        cyclic_gaits.GaitTable.load(missing)
    garbage = tmp_path / "garbage.json"
    garbage.write_text("{not json")
    with pytest.raises(InputError, match="garbage.json"):
        cyclic_gaits.GaitTable.load(garbage)
    partial = tmp_path / "partial.json"
    partial.write_text(json.dumps({"speeds": [1, 2]}))
    with pytest.raises(InputError, match="partial.json"):
        cyclic_gaits.GaitTable.load(partial)


def test_bilinear_impulse_fit_matches_the_table(table: cyclic_gaits.GaitTable) -> None:
    coef, rms = cyclic_gaits.fit_impulse_mean(table)
    pts = table.converged_points()
    assert rms < 0.02                       # m/s; solved iotas span 0.15-1.15 m/s
    assert rms < 0.1 * np.std(pts["toe_off_impulse"])
    pred = coef[0] + coef[1] * pts["pre_stance_rate"] + coef[2] * pts["pre_swing_rate"] \
        + coef[3] * pts["pre_stance_rate"] * pts["pre_swing_rate"]
    assert np.sqrt(np.mean((pred - pts["toe_off_impulse"]) ** 2)) == pytest.approx(rms)


def test_step_map_radius_predicts_growth_of_perturbations(table: cyclic_gaits.GaitTable) -> None:
    """Radius < 1: a perturbed gait returns; radius > 1: it drifts away (10 steps, fixed kappa/iota)."""
    assert table.step_map_radius is not None and np.all(np.isfinite(table.step_map_radius[table.converged]))
    for speed, step in ((4 / 3.6, 0.6), (6 / 3.6, 0.75)):
        i = int(np.argmin(np.abs(table.speeds - speed)))
        j = int(np.argmin(np.abs(table.step_lengths - step)))
        x = np.array([table.stance_rate[i, j], table.swing_rate[i, j], table.stiffness[i, j],
                      table.toe_off_impulse[i, j]])
        radius = cyclic_gaits.step_map_radius(PARAMS, table.speeds[i], table.step_lengths[j], x)
        assert radius == pytest.approx(table.step_map_radius[i, j], rel=1e-3)
        a = float(cyclic_gaits.double_support_angle(PARAMS, table.step_lengths[j]))
        nominal = np.array([a, x[0], x[1]])
        state = WalkerState.from_arrays(a, -a, x[0] + 1e-4, x[1])
        deviations = []
        for _ in range(10):
            state, _, _ = dynamics.simulate_to_strike(PARAMS, state, x[2], x[3], step=cyclic_gaits.SOLVER_STEP)
            deviations.append(np.abs(np.array([state.stance_angle[0], state.stance_rate[0], state.swing_rate[0]])
                                     - nominal).max())
        growth = deviations[-1] / deviations[1]
        assert (growth < 1.0) == (radius < 1.0), (radius, deviations)


def test_packaged_table_is_symmetric_and_unstable_from_5_kmh_where_an_asymmetric_gait_is_stable(
        table: cyclic_gaits.GaitTable) -> None:
    """From 5 km/h eq. (3) has, beside the table's mirror-symmetric gait (radius > 1), an asymmetric one
    that is stable (kappa as solved independently in issue 10); Newton finds it from that kappa."""
    for speed, step, kappa in ((5 / 3.6, 0.7, 0.749), (6 / 3.6, 0.75, 1.086)):
        i = int(np.argmin(np.abs(table.speeds - speed)))
        j = int(np.argmin(np.abs(table.step_lengths - step)))
        x = np.array([table.stance_rate[i, j], table.swing_rate[i, j], table.stiffness[i, j],
                      table.toe_off_impulse[i, j]])
        np.testing.assert_allclose([table.pre_stance_rate[i, j], table.pre_swing_rate[i, j]], x[:2], atol=1e-5)
        assert cyclic_gaits.step_map_radius(PARAMS, table.speeds[i], table.step_lengths[j], x) > 1.05
        other = cyclic_gaits.solve_point(PARAMS, table.speeds[i], table.step_lengths[j], np.array([*x[:2], kappa, x[3]]))
        assert other.converged and not cyclic_gaits.is_symmetric(other)
        assert other.unknowns[2] == pytest.approx(kappa, abs=2e-3)
        assert cyclic_gaits.step_map_radius(PARAMS, table.speeds[i], table.step_lengths[j], other.unknowns) < 0.95


def test_stable_family_reaches_the_asymmetric_gaits_from_a_symmetric_seed() -> None:
    """Continuation from 4.5 km/h (symmetric, stable) into 5-5.5 km/h, where only the asymmetric gait is stable."""
    speeds = np.array([4.5, 5.0, 5.5]) / 3.6
    steps = np.array([0.65, 0.7])
    kept = {}
    for family in ("stable", "symmetric"):
        kept[family] = cyclic_gaits.solve_grid(PARAMS, speeds, steps, seed_point=(4.5 / 3.6, 0.65), family=family)
        assert kept[family].converged.all() and np.all(kept[family].residual < 1e-8)
    assert np.all(kept["stable"].step_map_radius[1:] < 1.0)
    assert np.all(kept["symmetric"].step_map_radius[1:] > 1.0)
    assert kept["stable"].stiffness[1, 1] == pytest.approx(0.749, abs=2e-3)      # 5 km/h, 0.7 m
    assert kept["symmetric"].stiffness[1, 1] == pytest.approx(0.737, abs=2e-3)
    # kappa still rises with speed in the stable family (gait_for_stiffness inverts it)
    assert np.all(np.diff(kept["stable"].stiffness, axis=0) > 0)
    np.testing.assert_allclose(kept["stable"].stiffness[0], kept["symmetric"].stiffness[0])   # same at 4.5 km/h
    with pytest.raises(ValueError, match="family"):
        cyclic_gaits.solve_grid(PARAMS, speeds, steps, family="smooth")


def test_table_scaled_to_another_leg_length_is_cyclic(table: cyclic_gaits.GaitTable) -> None:
    """Dimensional analysis: the rescaled entries solve eq. (3) for the new walker, re-simulated."""
    child = WalkerParams(leg_length=0.62, gravity=9.8)
    scaled = table.scaled_to(child)
    assert scaled.params == child and table.scaled_to(PARAMS) is table
    assert scaled.step_lengths[-1] == pytest.approx(1.2 * 0.62 / 0.9)
    for i, j in ((2, 4), (5, 8), (9, 14)):
        x = np.array([scaled.stance_rate[i, j], scaled.swing_rate[i, j], scaled.stiffness[i, j],
                      scaled.toe_off_impulse[i, j]])
        residual = cyclic_gaits.cyclic_residual(child, scaled.speeds[i], scaled.step_lengths[j], x)
        assert np.max(np.abs(residual)) < 1e-6
        # and the unscaled entry is not cyclic for the child (the test can tell)
        wrong = np.array([table.stance_rate[i, j], table.swing_rate[i, j], table.stiffness[i, j],
                          table.toe_off_impulse[i, j]])
        assert np.max(np.abs(cyclic_gaits.cyclic_residual(child, scaled.speeds[i], scaled.step_lengths[j], wrong))) > 1e-3
    with pytest.raises(ValueError, match="only leg_length and gravity"):
        table.scaled_to(WalkerParams(foot_radius_ratio=0.2))


def test_covers_and_lookup_agree_on_unconverged_cells(table: cyclic_gaits.GaitTable) -> None:
    import dataclasses

    holed = dataclasses.replace(table, converged=table.converged.copy())
    holed.converged[:3, :4] = False                       # slow, short-step corner without gaits
    inside, edge, outside = (table.speeds[1], table.step_lengths[1]), (table.speeds[3], table.step_lengths[3]), \
        (table.speeds[6], table.step_lengths[8])
    covered = holed.covers(np.array([inside[0], edge[0], outside[0]]), np.array([inside[1], edge[1], outside[1]]))
    assert covered.tolist() == [False, True, True]
    with pytest.raises(InputError, match="no converged gait near speed"):
        holed.lookup(*inside)
    np.testing.assert_allclose(holed.lookup(*outside), table.lookup(*outside))
    # broadcasting: speeds (S,) against step lengths (K, 1)
    assert holed.covers(table.speeds, table.step_lengths[:, None]).shape == (table.step_lengths.size, table.speeds.size)


def _reference_lookup(table: cyclic_gaits.GaitTable, speed: np.ndarray, step: np.ndarray) -> np.ndarray:
    """Straightforward bilinear look-up over the converged corners (the oracle of the compiled one): (4, M)."""
    out = np.empty((4, speed.size))
    for q, (v, s) in enumerate(zip(speed, step)):
        v, s = np.clip(v, table.speeds[0], table.speeds[-1]), np.clip(s, table.step_lengths[0], table.step_lengths[-1])
        i = min(np.searchsorted(table.speeds, v, side="right") - 1, table.speeds.size - 2)
        j = min(np.searchsorted(table.step_lengths, s, side="right") - 1, table.step_lengths.size - 2)
        tv = (v - table.speeds[i]) / (table.speeds[i + 1] - table.speeds[i])
        ts = (s - table.step_lengths[j]) / (table.step_lengths[j + 1] - table.step_lengths[j])
        total, acc = 0.0, np.zeros(4)
        for ci, cj, w in ((i, j, (1 - tv) * (1 - ts)), (i + 1, j, tv * (1 - ts)), (i, j + 1, (1 - tv) * ts),
                          (i + 1, j + 1, tv * ts)):
            if table.converged[ci, cj]:
                total += w
                acc += w * np.array([table.stance_rate[ci, cj], table.swing_rate[ci, cj], table.stiffness[ci, cj],
                                     table.toe_off_impulse[ci, cj]])
        out[:, q] = acc / total
    return out


def test_compiled_lookups_agree_with_a_reference_on_random_queries(table: cyclic_gaits.GaitTable) -> None:
    rng = np.random.default_rng(7)
    speed = np.concatenate([rng.uniform(0.2, 2.4, 300), table.speeds])        # beyond the grid and on its points
    step = np.concatenate([rng.uniform(0.3, 1.4, 300), rng.choice(table.step_lengths, table.speeds.size)])
    np.testing.assert_allclose(np.array(table.lookup(speed, step)), _reference_lookup(table, speed, step),
                               rtol=1e-12, atol=1e-12)
    # gait_for_stiffness: kappa along the speed axis at each step length, crossed where it meets the asked kappa
    kappa = rng.uniform(table.stiffness.min() - 0.3, table.stiffness.max() + 0.3, 300)
    step = step[:300]
    found, stance_rate, swing_rate, iota = table.gait_for_stiffness(kappa, step)
    along = np.stack([_reference_lookup(table, np.full(step.size, v), step)[2] for v in table.speeds], axis=1)
    below = np.clip((along < kappa[:, None]).sum(1) - 1, 0, table.speeds.size - 2)
    rows = np.arange(kappa.size)
    fraction = np.clip((kappa - along[rows, below]) / (along[rows, below + 1] - along[rows, below]), 0, 1)
    expected = table.speeds[below] + fraction * np.diff(table.speeds)[below]
    np.testing.assert_allclose(found, expected, rtol=1e-12)
    np.testing.assert_allclose(np.array([stance_rate, swing_rate, iota]),
                               _reference_lookup(table, expected, step)[[0, 1, 3]], rtol=1e-12, atol=1e-12)
    inside = (kappa > along[:, 0]) & (kappa < along[:, -1])
    np.testing.assert_allclose(table.lookup(found, step)[2][inside], kappa[inside], rtol=1e-9)   # it inverts
