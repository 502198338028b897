"""Python on every architecture of the paper's §3 (one ADC, G ADCs, tiles, a coded aperture;
codes as int8, packed bytes or a seed), with the same results as the command line.

The command line is found through the environment variable RDLIDAR_BIN (the path of the
`rdlidar` binary, e.g. target/release/rdlidar); these tests fail, never skip, without it.
"""

import json
import math
import os
import re
import subprocess

import numpy as np
import pytest

import rdlidar
from conftest import numpy_adjoint, numpy_forward

SIZE = (8, 8, 6)  # the simulations compared file by file and the operators
KP = 200
SEED = 11
REC_SIZE = (12, 12, 8)  # the reconstructions (exact where the data allow)
REC_KP = 300

#: The architectures of the paper's §3, as keyword arguments of simulate.
ARCHS = {
    "one-adc": {},
    "adcs3": {"adcs": 3},
    "tiles4x4": {"tiles": (4, 4)},
    "tiles3x5": {"tiles": (3, 5)},  # clipped at the bottom and right edges
    "aperture": {"aperture": 0.5},
}


def formats_of(arch):
    """The codes formats an architecture allows: packed and seed hold +-1 codes only, not the
    zero codes of a coded aperture's blocked pixels."""
    return ("int8",) if "aperture" in ARCHS[arch] else rdlidar.CODES_FORMATS


ARCH_FORMATS = [(a, f) for a in ARCHS for f in formats_of(a)]


def run_cli(binary, *args):
    out = subprocess.run([binary, *map(str, args)], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, f"rdlidar {' '.join(map(str, args))}: {out.stderr}"
    return out


def cli_flags(kwargs):
    """The command line's flags of simulate's keyword arguments."""
    flags = []
    for key, value in kwargs.items():
        if key == "adcs":
            flags += ["--adcs", value]
        elif key == "tiles":
            flags += ["--tiles", f"{value[0]}x{value[1]}"]
        elif key == "aperture":
            flags += ["--aperture", value]
        elif key == "codes_format":
            flags += ["--codes-format", value]
        elif key == "snr_db":
            flags += ["--snr-db", value]
        elif key == "ternary_zero_prob":
            flags += ["--ternary-zero-prob", value]
        elif key == "lit_fraction":
            flags += ["--lit-fraction", value]
        elif key in ("photons", "background", "adc_bits", "full_scale"):
            flags += ["--" + key.replace("_", "-"), value]
        elif key in ("depth_png", "reflectivity_png"):
            flags += ["--" + key.replace("_", "-"), value]
        elif key == "dtype":
            flags += ["--precision", "f32" if np.dtype(value) == np.float32 else "f64"]
        else:
            raise AssertionError(f"no flag for {key}")
    return flags


def cli_simulate(binary, out, scene, size, pulse_len, seed, **kwargs):
    run_cli(binary, "simulate", "--scene", scene, "--size", "x".join(map(str, size)),
            "--pulse-len", pulse_len, "--seed", seed, "--out", out, "--quiet",
            *cli_flags(kwargs))


def tile_slices(m, n, tile):
    """The pixels of each tile of a tiled acquisition, in row-major tile order, clipped."""
    a, b = tile
    return [(slice(r, min(r + a, m)), slice(c, min(c + b, n)))
            for r in range(0, m, a) for c in range(0, n, b)]


def expected_rows(kwargs, size):
    if "adcs" in kwargs:
        return kwargs["adcs"]
    if "tiles" in kwargs:
        a, b = kwargs["tiles"]
        return math.ceil(size[0] / a) * math.ceil(size[1] / b)
    return None


def expected_architecture(kwargs):
    if "adcs" in kwargs:
        return "multi_adc"
    if "tiles" in kwargs:
        return "tiles"
    return "single"  # a coded aperture is one ADC whose blocked pixels have zero codes


def model_forward(pulse, codes, x, tiles=None):
    """The numpy model: one ADC, the stack of one ADC per code set, or one ADC per tile."""
    if codes.ndim == 4:
        return np.stack([numpy_forward(pulse, c, x) for c in codes])
    if tiles is not None:
        return np.stack([numpy_forward(pulse, codes[r, c], x[r, c])
                         for r, c in tile_slices(*x.shape[:2], tiles)])
    return numpy_forward(pulse, codes, x)


def model_adjoint(pulse, codes, y, ks, tiles=None):
    if codes.ndim == 4:
        return sum(numpy_adjoint(pulse, c, y[g], ks) for g, c in enumerate(codes))
    if tiles is not None:
        x = np.zeros(codes.shape[:2] + (ks,))
        for t, (r, c) in enumerate(tile_slices(*codes.shape[:2], tiles)):
            x[r, c] = numpy_adjoint(pulse, codes[r, c], y[t], ks)
        return x
    return numpy_adjoint(pulse, codes, y, ks)


def rel(a, b):
    return np.linalg.norm(np.ravel(a) - np.ravel(b)) / max(np.linalg.norm(np.ravel(b)), 1e-300)


def truth_depth(scene):
    return np.where(scene.max(axis=2) > 0, scene.argmax(axis=2), -1).astype(np.int32)


# simulate(out=...) writes the command line's files --------------------------------------------

VARIANTS = {
    "plain": ("paper", {}),
    "f32-noisy": ("paper", {"dtype": np.float32, "snr_db": 20.0}),
    "ternary": ("transparent", {"ternary_zero_prob": 0.3}),
    "random": ("random", {"lit_fraction": 0.3, "snr_db": 35.0}),
    "photons-adc": ("paper", {"photons": 30.0, "background": 2.0, "snr_db": 40.0,
                              "adc_bits": 6, "full_scale": 40.0}),
}


def simulation_cases():
    for arch, fmt in ARCH_FORMATS:
        for variant, (_, extra) in VARIANTS.items():
            if "ternary_zero_prob" in extra and fmt != "int8":
                continue  # packed and seeded codes are +-1 codes
            yield pytest.param(arch, fmt, variant, id=f"{arch}-{fmt}-{variant}")


@pytest.mark.parametrize("arch,fmt,variant", list(simulation_cases()))
def test_simulate_writes_the_command_lines_files_byte_for_byte(tmp_path, rdlidar_bin, arch,
                                                                 fmt, variant):
    scene, extra = VARIANTS[variant]
    kwargs = {**ARCHS[arch], "codes_format": fmt, **extra}
    cli_dir, py_dir = tmp_path / "cli", tmp_path / "py"
    cli_simulate(rdlidar_bin, cli_dir, scene, SIZE, KP, SEED, **kwargs)
    sim = rdlidar.simulate(scene, size=SIZE, pulse_len=KP, seed=SEED, out=py_dir, **kwargs)

    names = {"scene.npy", "pulse.npy", "meas.npy", "meta.json"}
    if fmt != "seed":
        names.add("codes.npy")
    assert set(os.listdir(cli_dir)) == names
    assert set(os.listdir(py_dir)) == names
    for name in sorted(names):
        assert (py_dir / name).read_bytes() == (cli_dir / name).read_bytes(), name

    # What simulate returns is what it wrote.
    assert sim.files == os.fspath(py_dir)
    dtype = np.dtype(extra.get("dtype", np.float64))
    for name in ("scene", "pulse", "meas"):
        got, written = getattr(sim, name), np.load(py_dir / f"{name}.npy")
        assert got.dtype == written.dtype == dtype, name
        assert got.shape == written.shape and np.array_equal(got, written), name
    if fmt == "seed":
        assert sim.codes is None
    else:
        written = np.load(py_dir / "codes.npy")
        assert sim.codes.dtype == written.dtype == (np.uint8 if fmt == "packed" else np.int8)
        assert sim.codes.shape == written.shape and np.array_equal(sim.codes, written)
    with open(py_dir / "meta.json") as f:
        assert sim.meta == json.load(f)

    # The shapes of the architecture.
    m, n, ks = SIZE
    k = KP + ks - 1
    rows = expected_rows(kwargs, SIZE)
    assert sim.meas.shape == ((k,) if rows is None else (rows, k))
    assert sim.tiles == kwargs.get("tiles")
    if fmt != "seed":
        last = k if fmt == "int8" else (k + 7) // 8
        want = (m, n, last) if "adcs" not in kwargs else (kwargs["adcs"], m, n, last)
        assert sim.codes.shape == want
    if "aperture" in kwargs:
        blocked = ~sim.codes.any(axis=-1)
        assert blocked.sum() == m * n - math.ceil(0.5 * m * n)
        assert sim.meta["architecture"]["kind"] == "aperture"


def test_simulate_in_memory_is_simulate_to_files(tmp_path):
    for kwargs in ARCHS.values():
        a = rdlidar.simulate("paper", size=SIZE, pulse_len=KP, seed=SEED, **kwargs)
        b = rdlidar.simulate("paper", size=SIZE, pulse_len=KP, seed=SEED, out=tmp_path / "x",
                             force=True, **kwargs)
        assert a.files is None
        for name in ("scene", "pulse", "codes", "meas"):
            assert np.array_equal(getattr(a, name), getattr(b, name)), name
        assert a.meta == b.meta


def write_png16(path, image):
    """A 16-bit grayscale PNG of a 2-D array of integers in [0, 65535]."""
    import struct
    import zlib

    h, w = image.shape
    raw = b"".join(b"\x00" + image[i].astype(">u2").tobytes() for i in range(h))

    def chunk(kind, data):
        crc = zlib.crc32(kind + data) & 0xFFFFFFFF
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", crc)

    header = struct.pack(">IIBBBBB", w, h, 16, 0, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header)
                     + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


def test_a_png_scene_is_the_command_lines_and_bad_maps_name_their_argument(tmp_path,
                                                                           rdlidar_bin):
    rng = np.random.default_rng(12)
    m, n, ks = SIZE
    depth = np.where(rng.random((m, n)) < 0.3, 0, rng.integers(1, 65536, (m, n)))
    refl = rng.integers(8000, 65536, (m, n))
    write_png16(tmp_path / "depth.png", depth)
    write_png16(tmp_path / "refl.png", refl)
    maps = {"depth_png": tmp_path / "depth.png", "reflectivity_png": tmp_path / "refl.png"}
    cli_dir, py_dir = tmp_path / "cli", tmp_path / "py"
    cli_simulate(rdlidar_bin, cli_dir, "png", SIZE, KP, SEED, snr_db=20.0, **maps)
    sim = rdlidar.simulate("png", size=SIZE, pulse_len=KP, seed=SEED, snr_db=20.0, out=py_dir,
                           **maps)
    for name in ("scene.npy", "pulse.npy", "codes.npy", "meas.npy", "meta.json"):
        assert (py_dir / name).read_bytes() == (cli_dir / name).read_bytes(), name
    lit = depth > 0
    bins = np.rint(depth / 65535 * (ks - 1)).astype(int)
    assert np.array_equal(truth_depth(sim.scene), np.where(lit, bins, -1))
    assert np.allclose(sim.scene.max(axis=2), np.where(lit, refl / 65535, 0))
    assert sim.meta["scene"]["source"] == "depth depth.png, reflectivity refl.png"

    wrong = (m, n + 1, ks)
    with pytest.raises(ValueError, match=r"depth_png: .*depth\.png is"):
        rdlidar.simulate("png", size=wrong, pulse_len=KP, depth_png=maps["depth_png"])
    (tmp_path / "bad.png").write_bytes(b"not a png")
    with pytest.raises(ValueError, match=r"reflectivity_png: .*bad\.png: not a readable PNG"):
        rdlidar.simulate("png", size=SIZE, pulse_len=KP, depth_png=maps["depth_png"],
                         reflectivity_png=tmp_path / "bad.png")
    with pytest.raises(ValueError, match="depth_png"):
        rdlidar.simulate("png", size=SIZE, pulse_len=KP)
    with pytest.raises(ValueError, match='depth_png: applies only to scene="png"'):
        rdlidar.simulate("paper", size=SIZE, pulse_len=KP, depth_png=maps["depth_png"])
    with pytest.raises(TypeError, match="depth_png: expected a path"):
        rdlidar.simulate("png", size=SIZE, pulse_len=KP, depth_png=3)


# The operator of every architecture ----------------------------------------------------------


def operators_of(sim, kwargs, fmt, folder, dtype=np.float64):
    """Every way to build the operator of a simulation: from its arrays and from its files."""
    ks = sim.scene.shape[2]
    tiles = kwargs.get("tiles")
    ops = {"sim.operator()": sim.operator(dtype=dtype)}
    if sim.codes is not None:
        ops["arrays"] = rdlidar.RdOperator(sim.pulse, sim.codes, ks, dtype=dtype, tiles=tiles)
        ops["codes.npy"] = rdlidar.RdOperator(sim.pulse, folder / "codes.npy", ks, dtype=dtype,
                                              tiles=tiles)
        ops["codes.npy as str"] = rdlidar.RdOperator(
            sim.pulse, os.fspath(folder / "codes.npy"), ks, dtype=dtype, tiles=tiles)
    else:
        ops["meta.json"] = rdlidar.RdOperator(sim.pulse, folder / "meta.json", ks, dtype=dtype)
        ops["meta.json, tiles"] = rdlidar.RdOperator(sim.pulse, os.fspath(folder / "meta.json"),
                                                     ks, dtype=dtype, tiles=tiles)
        if "adcs" not in kwargs and "tiles" not in kwargs:
            ops["meta.json, streamed"] = rdlidar.RdOperator(
                sim.pulse, folder / "meta.json", ks, dtype=dtype, stream_codes=True)
    return ops


@pytest.mark.parametrize("arch,fmt", ARCH_FORMATS)
def test_the_operator_of_every_architecture_measures_the_simulation(tmp_path, arch, fmt):
    kwargs = {**ARCHS[arch], "codes_format": fmt}
    folder = tmp_path / "sim"
    sim = rdlidar.simulate("paper", size=SIZE, pulse_len=KP, seed=SEED, out=folder, **kwargs)
    m, n, ks = SIZE
    k = KP + ks - 1
    rows = expected_rows(kwargs, SIZE)
    meas_shape = (k,) if rows is None else (rows, k)
    rng = np.random.default_rng(5)
    y = rng.standard_normal(meas_shape)
    ops = operators_of(sim, kwargs, fmt, folder)
    assert len(ops) >= 3
    reference = None
    for how, op in ops.items():
        assert op.shape == ((rows or 1) * k, m * n * ks), how
        assert op.meas_shape == meas_shape, how
        assert op.rows == rows, how
        assert op.architecture == expected_architecture(kwargs), how
        assert op.tiles == kwargs.get("tiles"), how
        assert op.scene_shape == SIZE and op.samples == k and op.dtype == np.float64, how
        assert op.streamed == how.endswith("streamed"), how
        got = op.forward(sim.scene)
        assert got.shape == meas_shape and got.dtype == np.float64, how
        assert rel(got, sim.meas) <= 1e-12, how
        assert np.array_equal(op.forward(sim.scene.ravel()), got), how
        assert np.array_equal(op.matvec(sim.scene.ravel()), got.ravel()), how
        back = op.adjoint(y)
        assert back.shape == SIZE and back.dtype == np.float64, how
        assert np.array_equal(op.adjoint(y.ravel()), back), how
        assert np.array_equal(op.rmatvec(y.ravel()), back.ravel()), how
        if reference is None:
            reference = back
        assert rel(back, reference) <= 1e-12, how
        test = rdlidar.dot_test(op, seed=3)
        assert test["passed"], (how, test)
    # In float32 too.
    op32 = sim.operator(dtype=np.float32)
    assert op32.dtype == np.float32 and op32.meas_shape == meas_shape
    assert rel(op32.forward(sim.scene), sim.meas) < 2e-5
    assert rdlidar.dot_test(op32)["passed"]


def seeded_codes(pulse_len, meta_path, size):
    """The +-1 codes a seeded meta.json describes, read off its operator with a pulse of ones: a
    return at depth 0 of pixel (m, n) measures s[m, n, k] for k < K_p, one at depth K_s - 1 for
    k >= K_s - 1 (in its tile's row for tiles). Returns (M, N, K), or (G, M, N, K) for G code
    sets."""
    m, n, ks = size
    k = pulse_len + ks - 1
    op = rdlidar.RdOperator(np.ones(pulse_len), meta_path, ks, dtype=np.float64)
    sets = op.rows if op.architecture == "multi_adc" else 1
    out = np.zeros((sets, m, n, k))
    for i in range(m):
        for j in range(n):
            for d, samples in ((0, slice(0, pulse_len)), (ks - 1, slice(ks - 1, k))):
                x = np.zeros(size)
                x[i, j, d] = 1.0
                y = op.forward(x).reshape(-1, k)
                if op.architecture == "tiles":
                    y = y.sum(axis=0, keepdims=True)  # the pixel's tile's row only
                out[:, i, j, samples] = y[:, samples]
    out = out.astype(np.int8)
    return out if op.architecture == "multi_adc" else out[0]


@pytest.mark.parametrize("arch,fmt", ARCH_FORMATS)
def test_the_operator_of_every_architecture_is_the_numpy_model(tmp_path, arch, fmt):
    kwargs = {**ARCHS[arch], "codes_format": fmt}
    sim = rdlidar.simulate("paper", size=SIZE, pulse_len=KP, seed=SEED, out=tmp_path / "s",
                           **kwargs)
    if fmt == "seed":
        codes = seeded_codes(KP, tmp_path / "s" / "meta.json", SIZE)
        assert set(np.unique(codes)) == {-1, 1}
    elif fmt == "packed":
        codes = np.unpackbits(sim.codes, axis=-1, count=KP + SIZE[2] - 1).astype(np.int8) * 2 - 1
        # The same draws as int8 codes.
        twin = rdlidar.simulate("paper", size=SIZE, pulse_len=KP, seed=SEED, **ARCHS[arch])
        assert np.array_equal(codes, twin.codes) and np.array_equal(sim.meas, twin.meas)
    else:
        codes = sim.codes
    if "aperture" in kwargs:
        assert not codes.any(axis=-1).all()  # blocked pixels: zero codes
    tiles = kwargs.get("tiles")
    ks = SIZE[2]
    rng = np.random.default_rng(17)
    x = rng.standard_normal(SIZE)
    op = sim.operator(dtype=np.float64)
    y = rng.standard_normal(op.meas_shape)
    want_y = model_forward(sim.pulse, codes, x, tiles)
    assert want_y.shape == op.meas_shape
    assert rel(op.forward(x), want_y) < 1e-12
    assert rel(model_forward(sim.pulse, codes, sim.scene, tiles), sim.meas) < 1e-12
    assert rel(op.adjoint(y), model_adjoint(sim.pulse, codes, y, ks, tiles)) < 1e-12
    if codes.ndim == 4:
        # Row g is the one-ADC operator of code set g.
        for g in range(codes.shape[0]):
            one = rdlidar.RdOperator(sim.pulse, codes[g], ks, dtype=np.float64)
            assert rel(op.forward(x)[g], one.forward(x)) < 1e-12
    if tiles is not None:
        # Row t is the one-ADC operator of tile t on its pixels.
        for t, (r, c) in enumerate(tile_slices(SIZE[0], SIZE[1], tiles)):
            one = rdlidar.RdOperator(sim.pulse, codes[r, c], ks, dtype=np.float64)
            assert rel(op.forward(x)[t], one.forward(x[r, c])) < 1e-12
            assert rel(op.adjoint(np.eye(op.rows)[t][:, None] * y)[r, c], one.adjoint(y[t])) < 1e-12


@pytest.mark.parametrize("dtype,rtol", [(np.float32, 1e-4), (np.float64, 1e-10)])
@pytest.mark.parametrize("arch", ["adcs3", "tiles3x5"])
def test_pylops_dottest_of_multi_adc_and_tiled_operators(arch, dtype, rtol):
    pylops = pytest.importorskip("pylops")
    sim = rdlidar.simulate("paper", size=SIZE, pulse_len=KP, seed=SEED, **ARCHS[arch])
    op = sim.operator(dtype=dtype)
    Op = pylops.aslinearoperator(op)
    assert Op.shape == op.shape
    assert pylops.utils.dottest(Op, *op.shape, rtol=rtol, raiseerror=True)
    x = np.random.default_rng(2).standard_normal(op.shape[1]).astype(dtype)
    assert np.array_equal(Op @ x, op.forward(x).ravel())


def test_simulation_operator_of_seeded_codes_without_files():
    for kwargs in ({}, {"adcs": 2}, {"tiles": (3, 5)}):
        sim = rdlidar.simulate("paper", size=SIZE, pulse_len=KP, seed=SEED, codes_format="seed",
                               **kwargs)
        assert sim.codes is None and sim.files is None
        op = sim.operator()
        assert op.architecture == expected_architecture(kwargs) and op.tiles == sim.tiles
        assert op.meas_shape == sim.meas.shape
        assert rel(op.forward(sim.scene), sim.meas) <= 1e-12
        assert rdlidar.dot_test(op)["passed"]
        op32 = sim.operator(dtype=np.float32)
        assert op32.dtype == np.float32 and rel(op32.forward(sim.scene), sim.meas) < 2e-5
        depth, _, _ = rdlidar.reconstruct(op, None, sim.meas, None, solver="backprojection")
        assert depth.shape == SIZE[:2]
    streamed = rdlidar.simulate("paper", size=SIZE, pulse_len=KP, seed=SEED,
                                codes_format="seed").operator(stream_codes=True)
    assert streamed.streamed


# reconstruct from Python is rdlidar reconstruct -----------------------------------------------

# (id, simulate's keyword arguments, solver, max_iter, fill_unobserved, codes given as a path)
RECONSTRUCTIONS = [
    ("one-adc-auto", {}, "auto", None, False, False),
    ("one-adc-model-based", {}, "model-based", None, False, False),
    ("one-adc-backprojection", {}, "backprojection", None, False, False),
    ("one-adc-cgls", {}, "cgls", 5, False, True),
    ("one-adc-fista", {}, "fista", 10, False, False),
    ("one-adc-noisy-auto", {"snr_db": 30.0}, "auto", None, False, False),
    ("one-adc-packed-auto", {"codes_format": "packed"}, "auto", None, False, True),
    ("adcs3-auto", {"adcs": 3}, "auto", None, False, False),
    ("adcs3-cgls", {"adcs": 3}, "cgls", 5, False, True),
    ("adcs3-backprojection", {"adcs": 3}, "backprojection", None, False, False),
    ("adcs2-packed-model-based", {"adcs": 2, "codes_format": "packed"}, "model-based", None,
     False, False),
    ("tiles4x4-auto", {"tiles": (4, 4)}, "auto", None, False, False),
    ("tiles4x4-cgls", {"tiles": (4, 4)}, "cgls", 5, False, True),
    ("tiles5x7-model-based", {"tiles": (5, 7)}, "model-based", None, False, False),
    ("tiles5x7-backprojection", {"tiles": (5, 7)}, "backprojection", None, False, False),
    ("aperture-auto", {"aperture": 0.5}, "auto", None, False, False),
    ("aperture-model-based", {"aperture": 0.5}, "model-based", None, False, True),
    ("aperture-auto-filled", {"aperture": 0.5}, "auto", None, True, False),
    ("aperture-backprojection-filled", {"aperture": 0.5}, "backprojection", None, True, False),
    ("seed-auto", {"codes_format": "seed"}, "auto", None, False, True),
    ("seed-adcs2-model-based", {"codes_format": "seed", "adcs": 2}, "model-based", None, False,
     True),
    ("seed-tiles4x4-auto", {"codes_format": "seed", "tiles": (4, 4)}, "auto", None, False,
     True),
    ("seed-tiles4x4-cgls", {"codes_format": "seed", "tiles": (4, 4)}, "cgls", 5, False, True),
    # In float32 (--precision f32) too.
    ("f32-one-adc-auto", {"dtype": np.float32}, "auto", None, False, False),
    ("f32-adcs2-auto", {"dtype": np.float32, "adcs": 2}, "auto", None, False, False),
    ("f32-tiles4x4-cgls", {"dtype": np.float32, "tiles": (4, 4)}, "cgls", 5, False, False),
    ("f32-one-adc-fista", {"dtype": np.float32}, "fista", 10, False, False),
]

#: Where the noise-free data determine the scene and auto / model-based find it exactly.
EXACT = {"one-adc-auto", "one-adc-model-based", "one-adc-packed-auto", "adcs3-auto",
         "adcs2-packed-model-based", "tiles4x4-auto", "tiles5x7-model-based", "seed-auto",
         "seed-adcs2-model-based", "seed-tiles4x4-auto", "aperture-auto",
         "aperture-model-based", "f32-one-adc-auto", "f32-adcs2-auto"}


@pytest.mark.parametrize("case,kwargs,solver,max_iter,fill,by_path", RECONSTRUCTIONS,
                         ids=[r[0] for r in RECONSTRUCTIONS])
def test_reconstruct_is_the_command_line(tmp_path, rdlidar_bin, case, kwargs, solver, max_iter,
                                         fill, by_path):
    folder = tmp_path / "sim"
    kwargs = {"dtype": np.float64, **kwargs}
    dtype = np.dtype(kwargs["dtype"])
    sim = rdlidar.simulate("paper", size=REC_SIZE, pulse_len=REC_KP, seed=SEED, out=folder,
                           **kwargs)
    ks = REC_SIZE[2]
    seeded = kwargs.get("codes_format") == "seed"
    codes_file = folder / ("meta.json" if seeded else "codes.npy")
    tiles = kwargs.get("tiles")
    args = ["reconstruct", "--pulse", folder / "pulse.npy", "--codes", codes_file,
            "--meas", folder / "meas.npy", "--depth-bins", ks, "--solver", solver,
            "--out-depth", tmp_path / "d.npy", "--out-scene", tmp_path / "x.npy",
            "--precision", "f64" if dtype == np.float64 else "f32"]
    if max_iter is not None:
        args += ["--max-iter", max_iter]
    if tiles is not None:
        args += ["--tiles", f"{tiles[0]}x{tiles[1]}"]
    if fill:
        args += ["--fill-unobserved"]
    printed = run_cli(rdlidar_bin, *args).stdout
    cli_depth, cli_scene = np.load(tmp_path / "d.npy"), np.load(tmp_path / "x.npy")

    codes = sim.codes
    if seeded or by_path:  # the file, as a Path or (for cgls) a str
        codes = os.fspath(codes_file) if solver == "cgls" else codes_file
    depth, scene, report = rdlidar.reconstruct(sim.pulse, codes, sim.meas, ks, solver=solver,
                                               max_iter=max_iter, tiles=tiles,
                                               fill_unobserved=fill)
    assert depth.dtype == cli_depth.dtype == np.int32
    assert scene.dtype == cli_scene.dtype == dtype
    assert depth.shape == cli_depth.shape == REC_SIZE[:2]
    assert scene.shape == cli_scene.shape == REC_SIZE
    assert np.array_equal(depth, cli_depth), np.argwhere(depth != cli_depth)[:5]
    assert np.array_equal(scene, cli_scene), np.max(np.abs(scene - cli_scene))
    assert report["method"] == solver
    assert report["architecture"] == expected_architecture(kwargs)
    # The lines the command line prints, times aside.
    untimed = lambda line: re.sub(r"\d+\.\d+ s\b", "_ s", line)
    assert report["headline"].startswith(f"solver {report['method_used']}")
    for line in [report["headline"], *report["details"]]:
        assert untimed(line) in untimed(printed), (line, printed)

    # And from an operator: the same.
    d2, x2, _ = rdlidar.reconstruct(sim.operator(), None, sim.meas, None, solver=solver,
                                    max_iter=max_iter, fill_unobserved=fill)
    assert np.array_equal(d2, depth) and np.array_equal(x2, scene)

    truth = truth_depth(sim.scene)
    if "aperture" in kwargs:
        blocked = ~sim.codes.any(axis=-1)
        assert blocked.any() and (~blocked).any()
        if fill:
            assert not (depth == -2).any()
            assert 0 < report["filled"] == (depth[blocked] >= 0).sum()
        else:
            assert np.array_equal(depth == -2, blocked)
            assert report["filled"] == 0
        if case in EXACT:
            assert np.array_equal(depth[~blocked], truth[~blocked])
    elif case in EXACT:
        assert np.array_equal(depth, truth)
        assert rdlidar.metrics(sim.scene, scene)["relative_error"] < (
            1e-6 if dtype == np.float64 else 1e-3)


def test_the_aperture_unobserved_pixels_filled_or_not():
    sim = rdlidar.simulate("paper", size=REC_SIZE, pulse_len=REC_KP, seed=SEED, aperture=0.5)
    blocked = ~sim.codes.any(axis=-1)
    plain, _, _ = rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, REC_SIZE[2], solver="auto")
    filled, _, rep = rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, REC_SIZE[2],
                                         solver="auto", fill_unobserved=True)
    assert np.array_equal(plain == -2, blocked)
    assert np.array_equal(filled[~blocked], plain[~blocked])
    assert (filled[blocked] >= -1).all()
    assert 0 < rep["filled"] == (filled[blocked] >= 0).sum()


# Tiles: a report per tile, the callback told the tile ------------------------------------------


def test_reconstruct_with_tiles_reports_each_tile_and_tells_the_callback():
    tiles = (3, 5)
    sim = rdlidar.simulate("paper", size=SIZE, pulse_len=KP, seed=SEED, tiles=tiles)
    places = tile_slices(SIZE[0], SIZE[1], tiles)
    seen = []
    depth, scene, report = rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, SIZE[2],
                                               solver="cgls", max_iter=4, tiles=tiles,
                                               callback=seen.append)
    assert report["architecture"] == "tiles" and report["method"] == "cgls"
    assert len(report["tiles"]) == len(places) == 6
    for t, (info, (r, c)) in enumerate(zip(report["tiles"], places)):
        assert info["index"] == t
        assert (info["row"], info["col"]) == (r.start, c.start)
        assert tuple(info["shape"]) == (r.stop - r.start, c.stop - c.start)
        assert info["method_used"] == "cgls"
        assert 1 <= info["iterations"] <= 4
    assert seen and all("tile" in s for s in seen)
    assert {s["tile"] for s in seen} == set(range(len(places)))
    for t, info in enumerate(report["tiles"]):
        mine = [s for s in seen if s["tile"] == t]
        assert [s["iteration"] for s in mine] == list(range(1, info["iterations"] + 1))
        assert np.allclose([s["residual"] for s in mine], info["residual_history"])
    # The tiles together: the same as solving each tile's one-ADC problem on its own.
    for t, (r, c) in enumerate(places):
        d, x, _ = rdlidar.reconstruct(sim.pulse, sim.codes[r, c], sim.meas[t], SIZE[2],
                                      solver="cgls", max_iter=4)
        assert np.array_equal(depth[r, c], d) and np.allclose(scene[r, c], x, rtol=0,
                                                               atol=1e-12)
    # No tile key without tiles.
    one = rdlidar.simulate("paper", size=SIZE, pulse_len=KP, seed=SEED)
    plain = []
    rdlidar.reconstruct(one.pulse, one.codes, one.meas, SIZE[2], solver="cgls", max_iter=3,
                        callback=plain.append)
    assert plain and not any("tile" in s for s in plain)


def test_a_true_callback_return_stops_every_tile():
    tiles = (4, 4)
    sim = rdlidar.simulate("paper", size=SIZE, pulse_len=KP, seed=SEED, tiles=tiles)
    seen = []

    def stop(info):
        seen.append(info)
        return True

    _, _, report = rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, SIZE[2], solver="cgls",
                                       max_iter=10, tiles=tiles, callback=stop)
    assert len(report["tiles"]) == 4
    for info in report["tiles"]:
        assert info["iterations"] == 1 and info["termination"] == "Observer"
    assert sorted(s["tile"] for s in seen) == [0, 1, 2, 3]


def test_an_exception_in_the_callback_of_a_tiled_reconstruction_propagates():
    tiles = (4, 4)
    sim = rdlidar.simulate("paper", size=SIZE, pulse_len=KP, seed=SEED, tiles=tiles,
                           codes_format="seed")
    meta = sim.meta

    class Enough(Exception):
        pass

    calls = []

    def boom(info):
        calls.append(info)
        if info["tile"] == 2 or len(calls) > 3:
            raise Enough(f"tile {info['tile']}")

    with pytest.raises(Enough, match="tile"):
        rdlidar.reconstruct(sim.operator(), None, sim.meas, None, solver="cgls", max_iter=50,
                            callback=boom)
    # Stopped early: far from every tile's 50 iterations.
    assert len(calls) < 4 * 50
    assert meta == sim.meta
