"""simulate, reconstruct (every solver), metrics and the callback from Python."""

import numpy as np
import pytest

import rdlidar


def test_version_and_solvers():
    assert isinstance(rdlidar.__version__, str) and rdlidar.__version__.count(".") == 2
    assert "auto" in rdlidar.SOLVERS and "fista" in rdlidar.SOLVERS and "tv" in rdlidar.SOLVERS


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_simulate_gives_what_the_operator_measures(dtype):
    sim = rdlidar.simulate("paper", size=(12, 10, 8), pulse_len=600, seed=3, dtype=dtype)
    assert sim.scene.shape == (12, 10, 8) and sim.scene.dtype == np.dtype(dtype)
    assert sim.pulse.shape == (600,) and sim.codes.shape == (12, 10, 607)
    assert sim.codes.dtype == np.int8 and set(np.unique(sim.codes)) <= {-1, 1}
    assert sim.meas.shape == (607,) and sim.meas.dtype == np.dtype(dtype)
    assert sim.meta["pulse_len"] == 600 and sim.meta["scene"]["kind"] == "paper"
    assert sim.meta["k"] == 607 and sim.meta["architecture"]["kind"] == "single"
    y = sim.operator().forward(sim.scene)
    tol = 1e-5 if dtype == np.float32 else 1e-12
    assert np.linalg.norm(y - sim.meas) <= tol * np.linalg.norm(sim.meas)
    # The same seed, the same draws; another seed, other codes.
    again = rdlidar.simulate("paper", size=(12, 10, 8), pulse_len=600, seed=3, dtype=dtype)
    assert np.array_equal(again.codes, sim.codes) and np.array_equal(again.meas, sim.meas)
    other = rdlidar.simulate("paper", size=(12, 10, 8), pulse_len=600, seed=4, dtype=dtype)
    assert not np.array_equal(other.codes, sim.codes)
    noisy = rdlidar.simulate("transparent", size=(6, 5, 8), pulse_len=300, seed=1, snr_db=20)
    assert noisy.meta["noise"]["snr_db"] == 20 and noisy.meta["noise"]["model"] == "gaussian"
    ternary = rdlidar.simulate("random", size=(6, 5, 8), pulse_len=300, ternary_zero_prob=0.3,
                               lit_fraction=0.2)
    assert 0 in np.unique(ternary.codes)


@pytest.mark.parametrize("solver", rdlidar.SOLVERS)
def test_every_solver_reconstructs_and_the_exact_ones_are_exact(solver):
    sim = rdlidar.simulate("paper", size=(12, 10, 8), pulse_len=600, seed=21)
    depth, scene, report = rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, 8, solver=solver)
    assert depth.shape == (12, 10) and depth.dtype == np.int32
    assert scene.shape == (12, 10, 8) and np.isfinite(scene).all()
    assert report["method"] == solver and report["method_used"] in rdlidar.SOLVERS
    assert report["seconds"] > 0 and report["regime"] == "compressive"
    m = rdlidar.metrics(sim.scene, scene)
    if solver in ("auto", "support-ls", "tv", "model-based"):
        assert m["exact_fraction"] == 1.0 and m["false_detections"] == 0, m
        assert m["relative_error"] < 1e-6
        truth_depth = np.where(sim.scene.max(axis=2) > 0, sim.scene.argmax(axis=2), -1)
        assert np.array_equal(depth, truth_depth)
    if solver == "auto":
        assert report["stages"] and any(s["kept"] for s in report["stages"])
    if solver not in ("backprojection", "backprojection-debiased"):
        assert report["termination"]
        applications = [report[f"{k}_applies"] for k in ("forward", "adjoint", "support")]
        assert sum(applications) > 0, report
        # The model-based solver ends before its first iteration when the least squares on its
        # message-passing start already explains the data.
        if not (solver == "model-based" and report["termination"] == "Residual"):
            assert report["iterations"] >= 1, report


def test_packed_codes_and_an_operator_give_the_same_reconstruction():
    sim = rdlidar.simulate("paper", size=(8, 8, 6), pulse_len=300, seed=2)
    a = rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, 6, solver="fista")
    b = rdlidar.reconstruct(sim.pulse, np.packbits(sim.codes > 0, axis=-1), sim.meas, 6,
                            solver="fista")
    op = rdlidar.RdOperator(sim.pulse, sim.codes, 6, dtype=np.float64)
    c = rdlidar.reconstruct(op, None, sim.meas, None, solver="fista")
    for other in (b, c):
        assert np.array_equal(a[0], other[0]) and np.array_equal(a[1], other[1])


def test_the_callback_sees_iterations_and_can_stop():
    sim = rdlidar.simulate("paper", size=(8, 8, 6), pulse_len=300, seed=2)
    seen = []

    def cb(info):
        seen.append(info)

    _, _, report = rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, 6, solver="cgls",
                                       callback=cb)
    assert [s["iteration"] for s in seen] == list(range(1, report["iterations"] + 1))
    assert all(np.isfinite(s["residual"]) for s in seen)
    assert np.allclose([s["residual"] for s in seen], report["residual_history"])
    # A true return value stops the solver there.
    _, _, report = rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, 6, solver="fista",
                                       callback=lambda info: info["iteration"] >= 4)
    assert report["iterations"] == 4 and report["termination"] == "Observer"
    # max_iter bounds the iterations.
    _, _, report = rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, 6, solver="cgls",
                                       max_iter=3)
    assert report["iterations"] <= 3


def test_an_exception_in_the_callback_propagates():
    sim = rdlidar.simulate("paper", size=(8, 8, 6), pulse_len=300, seed=2)

    class Enough(Exception):
        pass

    def cb(info):
        if info["iteration"] == 2:
            raise Enough("stop here")

    with pytest.raises(Enough, match="stop here"):
        rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, 6, solver="fista", callback=cb)


def test_metrics_count_exact_missed_and_false():
    truth = np.zeros((2, 2, 5))
    truth[0, 0, 1] = 1.0
    truth[1, 1, 3] = 0.5
    est = np.zeros_like(truth)
    est[0, 0, 1] = 0.9
    est[0, 1, 2] = 0.2
    m = rdlidar.metrics(truth, est)
    assert (m["lit"], m["exact"], m["missed"], m["false_detections"]) == (2, 1, 1, 1)
    assert m["exact_fraction"] == 0.5
    assert m["within_one_fraction"] == 0.5


def test_clipped_samples_are_censored_as_on_the_command_line():
    # The paper scene at 32x32x16, 3.3 measurements per lit pixel, through an 8-bit ADC that
    # clips a quarter of the samples: fitting them leaves false returns; censoring recovers
    # every depth.
    clean = rdlidar.simulate("paper", size=(32, 32, 16), pulse_len=1800, seed=40)
    full_scale = 0.29 * np.abs(clean.meas).max()
    sim = rdlidar.simulate("paper", size=(32, 32, 16), pulse_len=1800, seed=40, adc_bits=8,
                           full_scale=full_scale)
    top = np.abs(sim.meas).max()
    clipped = int((np.abs(sim.meas) >= top).sum())
    assert clipped > 300
    fitted = rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, 16)
    assert "censored" not in fitted[2]
    for how in ("top", float(top)):
        depth, scene, report = rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, 16,
                                                   clipped=how)
        assert report["censored"] == clipped and len(report["censored_levels"]) == 1
        m = rdlidar.metrics(sim.scene, scene)
        f = rdlidar.metrics(sim.scene, fitted[1])
        assert m["exact_fraction"] >= 0.99 and m["false_detections"] < f["false_detections"], (m, f)
    for bad, error in [("bottom", ValueError), (0.0, ValueError), (-1, ValueError),
                       (float("nan"), ValueError), (np.inf, ValueError), (1e-300, ValueError),
                       ([1.0], TypeError), (True, TypeError)]:
        with pytest.raises(error, match="clipped"):
            rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, 16, clipped=bad)


def test_a_false_rate_tests_each_return_and_is_reported():
    sim = rdlidar.simulate("paper", size=(16, 16, 16), pulse_len=1200, seed=5)
    depth, scene, report = rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, 16,
                                               false_rate=0.01)
    d = report["detection"]
    assert d["false_rate"] == 0.01 and d["dropped"] == 0 and d["skipped"] is None
    assert abs(d["bar"] - 3.227218425963163) < 1e-9 and d["tested"] == int((sim.scene > 0).sum())
    assert rdlidar.metrics(sim.scene, scene)["exact_fraction"] == 1.0
    assert "detection" not in rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, 16)[2]
    for bad, error in [(0.0, ValueError), (1.0, ValueError), (float("nan"), ValueError),
                       (-0.5, ValueError), ("0.1", TypeError), (True, TypeError)]:
        with pytest.raises(error, match="false_rate"):
            rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, 16, false_rate=bad)


def test_the_photon_noise_model_reweights_by_the_light_and_is_reported():
    # 2.4 measurements per lit pixel under photon noise (20 per unit of intensity): the
    # residual's variance grows with the light, the estimate is refined on the weighted rows.
    sim = rdlidar.simulate("paper", size=(32, 32, 16), pulse_len=1305, seed=42, photons=20.0)
    _, plain, _ = rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, 16)
    _, scene, report = rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, 16, noise="photon")
    p = report["photon"]
    assert p["skipped"] is None and p["gain"] > 1.2 and p["slope_z"] >= 3.0
    assert p["background"] == 0.0 and 0.0 < p["light_share"] <= 1.0
    weighted = rdlidar.metrics(sim.scene, scene)
    unweighted = rdlidar.metrics(sim.scene, plain)
    assert weighted["relative_error"] < unweighted["relative_error"]
    assert weighted["exact_fraction"] > unweighted["exact_fraction"]
    assert "photon" not in rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, 16)[2]
    for kwargs, error, name in [({"noise": "poisson"}, ValueError, "noise"),
                                ({"noise": 1}, TypeError, "noise"),
                                ({"noise": "photon", "background": -1.0}, ValueError,
                                 "background"),
                                ({"noise": "photon", "background": float("nan")}, ValueError,
                                 "background"),
                                ({"background": 1.0}, ValueError, "background")]:
        with pytest.raises(error, match=name):
            rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, 16, **kwargs)
