"""Continuous depths on a test set the methods were not tuned on (real_scenes.py: three
windows of a real stereo depth map and two drawn scenes), at a size a test runs in seconds."""

import numpy as np
import pytest

import rdlidar
from real_scenes import scenes, write_depth_png

SIDE, BINS = 16, 12
SET = scenes(SIDE, SIDE)


def simulate(tmp_path, name, per_lit, kernel, snr_db=None):
    png = tmp_path / f"{name}.png"
    write_depth_png(png, SET[name])
    lit = int(np.count_nonzero(~np.isnan(SET[name])))
    pulse_len = int(round(per_lit * lit)) - BINS + 1
    return rdlidar.simulate("png", size=(SIDE, SIDE, BINS), pulse_len=pulse_len, seed=1,
                            depth_png=png, depth="continuous", kernel=kernel, snr_db=snr_db)


def test_the_set_holds_real_and_drawn_scenes_with_empty_pixels():
    assert len(SET) == 5
    for name, depth in SET.items():
        lit = ~np.isnan(depth)
        assert depth.shape == (SIDE, SIDE)
        assert np.all((depth[lit] > 0) & (depth[lit] <= 1)), name
        # Depths between bins, not on the grid.
        bins = depth[lit] * (BINS - 1)
        assert np.mean(np.abs(bins - np.rint(bins)) > 0.05) > 0.5, name
    assert sum(np.count_nonzero(np.isnan(d)) for d in SET.values()) > 0


@pytest.mark.parametrize("name", sorted(SET))
def test_the_triangle_noise_free_comes_back_exact_at_four_measurements_per_lit_pixel(
        tmp_path, name):
    sim = simulate(tmp_path, name, 4.0, "triangle")
    _, _, report = rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, BINS, kernel="triangle")
    m = rdlidar.range_metrics(sim.range, report["range"])
    assert (m["missed"], m["false_returns"]) == (0, 0), (name, m)
    assert m["rmse_bins"] <= 0.01, (name, m)


@pytest.mark.parametrize("name", ["sphere", "stairs"])
def test_the_triangle_noise_free_comes_back_exact_at_two_and_a_half_per_lit_pixel(tmp_path, name):
    # TV on the depth map over the response's atoms, at 32×32×24: exact on the two drawn
    # scenes on seeds 1 to 3 when this was written. The real windows are not yet at this size
    # (at 48×48×32 two of three are), nor the drawn ones at 16×16×12 on every pulse length.
    side, bins = 32, 24
    depth = scenes(side, side)[name]
    png = tmp_path / f"{name}.png"
    write_depth_png(png, depth)
    lit = int(np.count_nonzero(~np.isnan(depth)))
    sim = rdlidar.simulate("png", size=(side, side, bins), pulse_len=int(round(2.5 * lit)) - bins + 1,
                           seed=1, depth_png=png, depth="continuous", kernel="triangle")
    _, _, report = rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, bins, kernel="triangle")
    m = rdlidar.range_metrics(sim.range, report["range"])
    assert (m["missed"], m["false_returns"]) == (0, 0), (name, m)
    assert m["rmse_bins"] <= 0.01, (name, m)
    assert report["stages"][0]["method"] == "tv", report["stages"]


@pytest.mark.parametrize("name", sorted(SET))
def test_a_gaussian_response_at_twenty_db_stays_near_the_joint_bound_at_six_per_lit_pixel(
        tmp_path, name):
    sim = simulate(tmp_path, name, 6.0, "gaussian:0.8", snr_db=20)
    sigma = sim.meta["noise"]["sigma"]
    _, _, report = rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, BINS,
                                       kernel="gaussian:0.8")
    joint = rdlidar.depth_bound(sim.operator(), sim.range, sim.amplitude, "gaussian:0.8", sigma,
                                joint=True)
    m = rdlidar.range_metrics(sim.range, report["range"], joint)
    assert m["missed"] == 0 and m["false_returns"] <= 1, (name, m)
    assert m["rmse_over_bound"] <= GAUSSIAN_RATIO, (name, m)


# RMSE over the joint bound at most: 0.95 to 1.06 when this was written (16×16×12, seed 1).
GAUSSIAN_RATIO = 1.25


@pytest.mark.parametrize("name", ["sphere", "stairs"])
def test_a_gaussian_response_at_twenty_db_beats_one_and_a_half_bounds_at_three_per_lit_pixel(
        tmp_path, name):
    # The prior on the depth map inside the fit: at 32×32×24, seed 1, 0.84 (sphere) and 0.92
    # (stairs) times the bound with every other pixel known when this was written (without
    # the prior about 2). The real windows are not yet within it (the right one 1.65).
    side, bins = 32, 24
    depth = scenes(side, side)[name]
    png = tmp_path / f"{name}.png"
    write_depth_png(png, depth)
    lit = int(np.count_nonzero(~np.isnan(depth)))
    sim = rdlidar.simulate("png", size=(side, side, bins), pulse_len=int(round(3 * lit)) - bins + 1,
                           seed=1, depth_png=png, depth="continuous", kernel="gaussian:0.8",
                           snr_db=20)
    _, _, report = rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, bins,
                                       kernel="gaussian:0.8")
    bound = rdlidar.depth_bound(sim.operator(), sim.range, sim.amplitude, "gaussian:0.8",
                                sim.meta["noise"]["sigma"])
    m = rdlidar.range_metrics(sim.range, report["range"], bound)
    assert (m["missed"], m["false_returns"]) == (0, 0), (name, m)
    assert m["rmse_over_bound"] <= 1.5, (name, m)
