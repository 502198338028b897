"""Reflectors at continuous depths and the system's response, from Python as from the command
line: the same files byte for byte, range.npy among them, and the same errors."""

import os
import subprocess

import numpy as np
import pytest

import rdlidar

SIZE = (9, 11, 10)
KP = 80


def cli(binary, *args):
    return subprocess.run([binary, *map(str, args)], capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("scene,kwargs", [
    ("paper", {"depth": "continuous"}),
    ("transparent", {"depth": "continuous", "kernel": "gaussian:0.8"}),
    ("random", {"kernel": "gaussian:1.5", "lit_fraction": 0.7}),
])
def test_continuous_simulations_are_the_command_lines_byte_for_byte(tmp_path, rdlidar_bin,
                                                                     scene, kwargs):
    flags = []
    for key, value in kwargs.items():
        flags += ["--" + key.replace("_", "-"), value]
    out = cli(rdlidar_bin, "simulate", "--scene", scene, "--size", "x".join(map(str, SIZE)),
              "--pulse-len", KP, "--seed", 3, "--out", tmp_path / "cli", *flags)
    assert out.returncode == 0, out.stderr
    sim = rdlidar.simulate(scene, size=SIZE, pulse_len=KP, seed=3, out=tmp_path / "py", **kwargs)
    names = sorted(os.listdir(tmp_path / "cli"))
    assert "range.npy" in names and names == sorted(os.listdir(tmp_path / "py"))
    for name in names:
        assert (tmp_path / "py" / name).read_bytes() == (tmp_path / "cli" / name).read_bytes()
    written = np.load(tmp_path / "py" / "range.npy")
    assert sim.range.dtype == np.float64
    assert np.array_equal(sim.range, written, equal_nan=True)
    lit = ~np.isnan(sim.range)
    assert lit.any() and np.all(sim.range[lit] >= 0) and np.all(sim.range[lit] <= SIZE[2] - 1)
    if kwargs.get("depth") == "continuous":
        assert np.any(np.abs(sim.range[lit] - np.round(sim.range[lit])) > 0.05)
    else:
        assert np.array_equal(sim.range[lit], np.round(sim.range[lit]))
    if scene == "transparent":
        assert sim.range.ndim == 3 and sim.range.shape[1:] == SIZE[:2]


def test_the_triangle_splits_a_reflector_between_two_bins():
    sim = rdlidar.simulate("paper", size=SIZE, pulse_len=KP, depth="continuous")
    assert sim.meta["scene"]["kernel"] == "triangle"
    for (i, j), d in np.ndenumerate(sim.range):
        col = sim.scene[i, j]
        if np.isnan(d):
            assert not col.any()
            continue
        lo, f = int(np.floor(d)), d - np.floor(d)
        amp = col.sum()
        assert col[lo] == pytest.approx(amp * (1 - f), abs=1e-12)
        if f > 0:
            assert col[lo + 1] == pytest.approx(amp * f, abs=1e-12)
    # On the grid without a kernel, nothing changes: no range.
    assert rdlidar.simulate("paper", size=SIZE, pulse_len=KP).range is None


@pytest.mark.parametrize("kwargs,needle", [
    ({"depth": "continuous", "kernel": "delta"}, "depth"),
    ({"kernel": "gaussian:-1"}, "kernel"),
    ({"kernel": "measured:4:/no/such.npy"}, "/no/such.npy"),
    ({"depth": "sideways"}, "depth"),
])
def test_bad_depths_and_kernels_name_their_argument(kwargs, needle):
    with pytest.raises(ValueError) as e:
        rdlidar.simulate("paper", size=SIZE, pulse_len=KP, **kwargs)
    msg = str(e.value)
    assert needle in msg and "\n" not in msg, msg
    with pytest.raises(TypeError):
        rdlidar.simulate("paper", size=SIZE, pulse_len=KP, kernel=0.8)


@pytest.mark.parametrize("kernel", ["triangle", "gaussian:0.8"])
def test_reconstruct_under_a_kernel_returns_the_continuous_depths(tmp_path, rdlidar_bin, kernel):
    sim = rdlidar.simulate("paper", size=(8, 8, 8), pulse_len=900, seed=2, depth="continuous",
                           kernel=kernel, out=tmp_path / "s")
    depth, scene, report = rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, 8, kernel=kernel)
    est = report["range"]
    assert est.shape == sim.range.shape and est.dtype == np.float64
    assert np.array_equal(np.isnan(est), np.isnan(sim.range))
    lit = ~np.isnan(sim.range)
    assert np.max(np.abs(est[lit] - sim.range[lit])) < 1e-6
    assert np.array_equal(depth[lit], np.clip(np.round(est[lit]), 0, 7).astype(np.int32))
    # The command line writes the same depths.
    s = tmp_path / "s"
    out = cli(rdlidar_bin, "reconstruct", "--pulse", s / "pulse.npy", "--codes", s / "codes.npy",
              "--meas", s / "meas.npy", "--depth-bins", 8, "--solver", "auto", "--kernel", kernel,
              "--out-depth", tmp_path / "d.npy", "--out-scene", tmp_path / "x.npy",
              "--out-range", tmp_path / "r.npy")
    assert out.returncode == 0, out.stderr
    assert np.array_equal(np.load(tmp_path / "r.npy"), est, equal_nan=True)
    assert np.array_equal(np.load(tmp_path / "x.npy"), scene)
    # Without a kernel, no range.
    assert "range" not in rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, 8)[2]
    with pytest.raises(ValueError) as e:
        rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, 8, kernel=kernel, false_rate=0.01)
    assert "false_rate" in str(e.value)


def test_the_bound_and_the_depth_errors_are_the_command_lines(tmp_path, rdlidar_bin):
    sim = rdlidar.simulate("paper", size=(8, 8, 8), pulse_len=900, seed=3, depth="continuous",
                           kernel="gaussian:0.8", snr_db=20, out=tmp_path / "s")
    assert sim.amplitude.shape == sim.range.shape
    assert np.array_equal(sim.amplitude > 0, ~np.isnan(sim.range))
    sigma = sim.meta["noise"]["sigma"]
    depth, scene, report = rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, 8,
                                               kernel="gaussian:0.8")
    assert report["amplitude"].shape == report["range"].shape
    bound = rdlidar.depth_bound(sim.operator(), sim.range, sim.amplitude, "gaussian:0.8", sigma)
    assert bound.shape == (1, 8, 8)
    assert np.array_equal(np.isnan(bound[0]), np.isnan(sim.range))
    lit = ~np.isnan(sim.range)
    assert np.all((bound[0][lit] > 0) & np.isfinite(bound[0][lit]))
    # Twice the noise, twice the bound.
    twice = rdlidar.depth_bound(sim.operator(), sim.range, sim.amplitude, "gaussian:0.8",
                                2 * sigma)
    assert np.allclose(twice[0][lit], 2 * bound[0][lit], rtol=1e-12)
    m = rdlidar.range_metrics(sim.range, report["range"], bound, tau_s=1e-9)
    assert m["paired"] == lit.sum() and m["missed"] == 0
    assert 0.5 < m["rmse_over_bound"] < 2.0
    assert abs(m["rmse_m"] - m["rmse_bins"] * 0.299792458 / 2) < 1e-12
    # The command line prints the same figures.
    s = tmp_path / "s"
    out = cli(rdlidar_bin, "reconstruct", "--pulse", s / "pulse.npy", "--codes", s / "codes.npy",
              "--meas", s / "meas.npy", "--depth-bins", 8, "--solver", "auto", "--kernel",
              "gaussian:0.8", "--out-depth", tmp_path / "d.npy", "--out-scene",
              tmp_path / "x.npy", "--truth", s / "scene.npy", "--truth-range", s / "range.npy",
              "--noise-sigma", repr(sigma))
    assert out.returncode == 0, out.stderr
    line = next(l for l in out.stdout.splitlines() if l.startswith("versus the true depths:"))
    assert f"depth RMSE {m['rmse_bins']:.4f} bins" in line, line
    assert f"Cramér–Rao bound {m['bound_bins']:.4f} bins" in line, line
    assert f"RMSE/bound {m['rmse_over_bound']:.2f}" in line, line
    # With every return unknown at once: never below, and the command line's second figure.
    joint = rdlidar.depth_bound(sim.operator(), sim.range, sim.amplitude, "gaussian:0.8", sigma,
                                joint=True)
    assert np.array_equal(np.isnan(joint), np.isnan(bound))
    assert np.all(joint[0][lit] >= bound[0][lit] * (1 - 1e-9))
    j = rdlidar.range_metrics(sim.range, report["range"], joint, tau_s=1e-9)
    assert (f"with every return unknown at once the bound is {j['bound_bins']:.4f} bins" in line
            and f"RMSE/bound {j['rmse_over_bound']:.2f}" in line), line
    with pytest.raises(TypeError) as e:
        rdlidar.depth_bound(sim.operator(), sim.range, sim.amplitude, "gaussian:0.8", sigma,
                            joint="yes")
    assert str(e.value).startswith("joint"), str(e.value)


def test_points_are_the_ply_files_points(tmp_path, rdlidar_bin):
    plyfile = pytest.importorskip("plyfile")
    sim = rdlidar.simulate("transparent", size=(6, 7, 12), pulse_len=1500, seed=4,
                           depth="continuous", out=tmp_path / "s")
    s = tmp_path / "s"
    out = cli(rdlidar_bin, "reconstruct", "--pulse", s / "pulse.npy", "--codes", s / "codes.npy",
              "--meas", s / "meas.npy", "--depth-bins", 12, "--solver", "auto", "--kernel",
              "triangle", "--returns", "auto", "--out-depth", tmp_path / "d.npy", "--out-scene",
              tmp_path / "x.npy", "--out-range", tmp_path / "r.npy", "--out-points",
              tmp_path / "p.ply", "--fov", "30x25", "--tau", "500ps")
    assert out.returncode == 0, out.stderr
    _, _, report = rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, 12, kernel="triangle")
    assert np.array_equal(np.load(tmp_path / "r.npy"), report["range"], equal_nan=True)
    cloud, where = rdlidar.points(report["range"], report["amplitude"], fov=(30, 25),
                                  tau_s=500e-12, pixels=True)
    assert cloud.shape == (np.count_nonzero(~np.isnan(report["range"])), 4)
    assert where.shape == (cloud.shape[0], 2) and where.dtype == np.uint32
    v = plyfile.PlyData.read(str(tmp_path / "p.ply"))["vertex"]
    assert len(v) == cloud.shape[0]
    for k, name in enumerate(["x", "y", "z", "intensity"]):
        assert np.allclose(v[name], cloud[:, k].astype(np.float32), rtol=0, atol=0), name
    assert np.array_equal(v["row"], where[:, 0]) and np.array_equal(v["col"], where[:, 1])
    # The range of each point is its depth in metres.
    r = np.linalg.norm(cloud[:, :3], axis=1)
    d = report["range"] if report["range"].ndim == 3 else report["range"][None]
    depths = np.concatenate([np.sort(d[:, i, j][~np.isnan(d[:, i, j])])
                             for i in range(6) for j in range(7)])
    assert np.allclose(r, depths * 299792458 * 500e-12 / 2, rtol=1e-12)


@pytest.mark.parametrize("call,needle", [
    (lambda r, a, op: rdlidar.points(r, a), "fov"),
    (lambda r, a, op: rdlidar.points(r, a, fov=200), "fov"),
    (lambda r, a, op: rdlidar.points(r, a, pixel_pitch=1e-5, focal_length=0), "focal_length"),
    (lambda r, a, op: rdlidar.points(r, a[:, :4], fov=30), "amplitude"),
    (lambda r, a, op: rdlidar.points(r, a, fov=30, tau_s=-1), "tau_s"),
    (lambda r, a, op: rdlidar.depth_bound(op, r, a, "delta", 1.0), "kernel"),
    (lambda r, a, op: rdlidar.depth_bound(op, r, a, "triangle", -1.0), "sigma"),
    (lambda r, a, op: rdlidar.depth_bound(op, r + 20, a, "triangle", 1.0), "depth"),
    (lambda r, a, op: rdlidar.range_metrics(r[0], r), "truth"),
    (lambda r, a, op: rdlidar.range_metrics(r, r[:4]), "estimate"),
])
def test_bad_points_bounds_and_metrics_name_their_argument(call, needle):
    sim = rdlidar.simulate("paper", size=(6, 6, 8), pulse_len=200, depth="continuous")
    with pytest.raises(ValueError) as e:
        call(sim.range, sim.amplitude, sim.operator())
    assert str(e.value).startswith(needle), str(e.value)
