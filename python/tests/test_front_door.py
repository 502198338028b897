"""The Python front door: one test per Python defect of the issue (D05, D07, D09, D10, D11, D12
and the inputs of the architectures), each refused with a ValueError, TypeError or MemoryError
whose one-line message names the argument; none aborts the interpreter or returns a silent NaN.
"""

import json
import os
import subprocess
import sys
import textwrap
import warnings

import numpy as np
import pytest

import rdlidar
from conftest import random_problem


def one_line(excinfo, *needles):
    msg = str(excinfo.value)
    assert msg and "\n" not in msg, msg
    for n in needles:
        assert n in msg, msg


@pytest.fixture
def problem():
    return random_problem(3, 4, 5, 20, seed=1)  # K = 20 + 5 - 1 = 24


@pytest.fixture
def op(problem):
    pulse, codes = problem
    return rdlidar.RdOperator(pulse, codes, 5)


def run_python(code, env=None, timeout=120):
    """Runs `code` after CHILD_PRELUDE in a fresh interpreter: an abort there cannot take
    pytest down."""
    full_env = dict(os.environ)
    full_env.update(env or {})
    out = subprocess.run([sys.executable, "-c", CHILD_PRELUDE + textwrap.dedent(code)],
                         capture_output=True, text=True, timeout=timeout, env=full_env)
    assert out.returncode == 0, (
        f"the interpreter exited with status {out.returncode}"
        f"{' (killed by signal %d)' % -out.returncode if out.returncode < 0 else ''}:\n"
        f"{out.stdout}\n{out.stderr}")
    return out.stdout


# Each line the child prints: "<case>: <ExceptionType>: <message>" (or "<case>: no error").
CHILD_PRELUDE = """
import numpy as np
import rdlidar

def attempt(case, f):
    try:
        f()
    except Exception as e:
        print(f"{case}: {type(e).__name__}: {str(e)!r}", flush=True)
    else:
        print(f"{case}: no error", flush=True)
"""


def child_results(stdout):
    results = {}
    for line in stdout.splitlines():
        case, _, rest = line.partition(": ")
        kind, _, message = rest.partition(": ")
        results[case] = (kind, eval(message) if message else "")
    return results


def assert_memory_errors(results, cases):
    for case in cases:
        assert case in results, (case, results)
        kind, message = results[case]
        assert kind == "MemoryError", (case, kind, message)
        assert message and "\n" not in message and "memory" in message, (case, message)


# D05 ------------------------------------------------------------------------------------------


def test_d05_beyond_the_memory_available_is_a_memory_error_never_an_abort(tmp_path):
    # And seeded codes whose meta.json describes 4096x4096 pixels of 2048 depth bins.
    rdlidar.simulate("paper", size=(8, 8, 6), pulse_len=150, codes_format="seed",
                     out=tmp_path / "seed")
    with open(tmp_path / "seed" / "meta.json") as f:
        meta = json.load(f)
    meta.update(geometry={"m": 4096, "n": 4096, "ks": 2048}, size="4096x4096x2048",
                pulse_len=1, k=2048)
    with open(tmp_path / "big.json", "w") as f:
        json.dump(meta, f)
    stdout = run_python("""
    big = BIG
    codes = np.broadcast_to(np.uint8(0x55), (2048, 2048, 256))
    pulse = np.ones(1)
    attempt("adjoint", lambda: rdlidar.RdOperator(pulse, codes, 2048).adjoint(np.ones(2048)))
    attempt("adjoint f64", lambda: rdlidar.RdOperator(pulse, codes, 2048,
                                                      dtype=np.float64).adjoint(np.ones(2048)))
    attempt("forward", lambda: rdlidar.RdOperator(pulse, codes, 2048).matvec(
        np.broadcast_to(np.float32(1), (2048 * 2048 * 2048,))))
    attempt("reconstruct", lambda: rdlidar.reconstruct(pulse, codes, np.ones(2048), 2048))
    attempt("reconstruct f32", lambda: rdlidar.reconstruct(pulse, codes, np.ones(2048), 2048,
                                                           dtype=np.float32, solver="fista"))
    attempt("dot_test", lambda: rdlidar.dot_test(rdlidar.RdOperator(pulse, codes, 2048)))
    attempt("G code sets", lambda: rdlidar.RdOperator(
        pulse, np.broadcast_to(np.uint8(0x55), (4, 2048, 2048, 256)), 2048))
    attempt("tiles", lambda: rdlidar.RdOperator(pulse, codes, 2048, tiles=(64, 64)))
    attempt("int8", lambda: rdlidar.RdOperator(
        pulse, np.broadcast_to(np.int8(1), (2048, 2048, 2048)), 2048))
    attempt("seeded", lambda: rdlidar.RdOperator(pulse, big, 2048).adjoint(np.ones(2048)))
    attempt("seeded, streamed", lambda: rdlidar.RdOperator(pulse, big, 2048, stream_codes=True))
    attempt("seeded reconstruct", lambda: rdlidar.reconstruct(pulse, big, np.ones(2048), 2048))
    """.replace("BIG", repr(os.fspath(tmp_path / "big.json"))))
    assert_memory_errors(child_results(stdout), [
        "adjoint", "adjoint f64", "forward", "reconstruct", "reconstruct f32", "dot_test",
        "G code sets", "tiles", "int8", "seeded", "seeded, streamed", "seeded reconstruct"])


def test_d05_every_solver_checks_memory_before_allocating():
    # Under a budget of 26 MB (RDLIDAR_MEMORY_LIMIT), a 100x100x96 float64 operator fits (its
    # codes, working buffers and two scenes of 7.7 MB: what an application and the dot test
    # hold) but a solver's several scenes do not: reconstruct and fista must refuse it before
    # allocating them, or, with the memory really short, the interpreter would abort.
    stdout = run_python("""
    codes = np.broadcast_to(np.uint8(0x55), (100, 100, 12))
    op = rdlidar.RdOperator(np.ones(1), codes, 96, dtype=np.float64)
    attempt("adjoint", lambda: op.adjoint(np.ones(96)))
    attempt("dot_test", lambda: rdlidar.dot_test(op))
    for solver in ("backprojection", "cgls", "fista", "auto"):
        attempt("reconstruct " + solver,
                lambda: rdlidar.reconstruct(op, None, np.ones(96), None, solver=solver))
    attempt("fista", lambda: rdlidar.fista(op, np.ones(96), 0.1, niter=3))
    """, env={"RDLIDAR_MEMORY_LIMIT": "26000000"})
    results = child_results(stdout)
    assert results["adjoint"] == ("no error", "") and results["dot_test"] == ("no error", "")
    assert_memory_errors(results, ["reconstruct backprojection", "reconstruct cgls",
                                   "reconstruct fista", "reconstruct auto", "fista"])


# D07 ------------------------------------------------------------------------------------------


def test_d07_bounds_name_the_argument_and_the_bound(problem):
    pulse, codes = problem
    # depth_bins at most 65536, with codes of the K it gives.
    for ks in (65537, 100000):
        matching = np.ones((3, 4, 20 + ks - 1), dtype=np.int8)
        with pytest.raises(ValueError) as e:
            rdlidar.RdOperator(pulse, matching, depth_bins=ks)
        one_line(e, "depth_bins", "65536")
    assert rdlidar.RdOperator(pulse, np.ones((3, 4, 20 + 65535), np.int8), 65536).shape[1] == \
        3 * 4 * 65536
    # Codes of more than 4096 rows (or columns, or code sets), int8 or packed, 3-D or 4-D.
    for bad in (np.ones((4097, 1, 7), np.int8), np.ones((1, 4097, 7), np.int8),
                np.zeros((4097, 1, 1), np.uint8), np.ones((2, 4097, 1, 7), np.int8),
                np.broadcast_to(np.int8(1), (4097, 1, 1, 7))):
        with pytest.raises(ValueError) as e:
            rdlidar.RdOperator(np.ones(3), bad, 5)
        one_line(e, "codes", "4096")
    # simulate's size.
    for size, bound in (((4097, 1, 6), "4096"), ((1, 4097, 6), "4096"),
                        ((8, 8, 65537), "65536")):
        with pytest.raises(ValueError) as e:
            rdlidar.simulate(size=size, pulse_len=10)
        one_line(e, "size", bound)
    # depth_bins beyond its bound is refused as such, whatever the codes (as the command line's
    # --depth-bins is): not as a disagreement of the codes with a K of 100019 samples.
    for call in (lambda: rdlidar.RdOperator(pulse, codes, depth_bins=100000),
                 lambda: rdlidar.RdOperator(pulse, codes, depth_bins=2**63),
                 lambda: rdlidar.reconstruct(pulse, codes, np.zeros(24), 100000)):
        with pytest.raises(ValueError) as e:
            call()
        one_line(e, "depth_bins", "65536")


# D09 ------------------------------------------------------------------------------------------


def test_d09_pulses_and_measurements_that_are_not_light_or_underflow_are_refused(problem):
    pulse, codes = problem
    negative = pulse.copy()
    negative[2] = -1.0
    for dtype in (np.float32, np.float64):
        with pytest.raises(ValueError) as e:
            rdlidar.RdOperator(negative, codes, 5, dtype=dtype)
        one_line(e, "pulse", "2")
        with pytest.raises(ValueError) as e:
            rdlidar.RdOperator(np.zeros(20), codes, 5, dtype=dtype)
        one_line(e, "pulse")
        with pytest.raises(ValueError) as e:
            rdlidar.reconstruct(negative, codes, np.ones(24), 5, dtype=dtype)
        one_line(e, "pulse")
    # Underflow to all zeros in float32.
    tiny = pulse * 1e-300
    with pytest.raises(ValueError) as e:
        rdlidar.RdOperator(tiny, codes, 5, dtype=np.float32)
    one_line(e, "pulse", "underflow")
    with pytest.raises(ValueError) as e:
        rdlidar.reconstruct(tiny, codes, np.ones(24), 5, dtype=np.float32)
    one_line(e, "pulse")
    y = np.full(24, 1e-300)
    with pytest.raises(ValueError) as e:
        rdlidar.reconstruct(pulse, codes, y, 5, dtype=np.float32)
    one_line(e, "meas", "underflow")
    op32 = rdlidar.RdOperator(pulse, codes, 5, dtype=np.float32)
    with pytest.raises(ValueError) as e:
        rdlidar.reconstruct(op32, None, y, None)
    one_line(e, "meas")
    with pytest.raises(ValueError) as e:
        rdlidar.fista(op32, y, 0.1)
    one_line(e, "meas")
    # The same values are valid in float64.
    op64 = rdlidar.RdOperator(tiny, codes, 5, dtype=np.float64)
    assert np.array_equal(op64.pulse, tiny)
    x = np.random.default_rng(1).random((3, 4, 5))
    got = op64.forward(x)
    assert np.isfinite(got).all() and got.any()
    depth, scene, _ = rdlidar.reconstruct(pulse, codes, y, 5, dtype=np.float64,
                                          solver="backprojection")
    assert depth.shape == (3, 4) and np.isfinite(scene).all()
    depth, scene, _ = rdlidar.reconstruct(pulse, codes, y, 5, solver="cgls", max_iter=3)
    assert scene.dtype == np.float64 and np.isfinite(scene).all()


# D10 ------------------------------------------------------------------------------------------


def test_d10_non_finite_inputs_and_overflowing_results_are_refused(problem):
    pulse, codes = problem
    for dtype in (np.float32, np.float64):
        op = rdlidar.RdOperator(pulse, codes, 5, dtype=dtype)
        for bad in (np.nan, np.inf, -np.inf):
            x = np.zeros(60, dtype=dtype)
            x[7] = bad
            for apply in (op.matvec, op.forward, op.__matmul__, op.H.rmatvec):
                with pytest.raises(ValueError) as e:
                    apply(x)
                one_line(e, "x", "7")
            y = np.zeros(24, dtype=dtype)
            y[3] = bad
            for apply in (op.rmatvec, op.adjoint, op.H.matvec):
                with pytest.raises(ValueError) as e:
                    apply(y)
                one_line(e, "y", "3")
        # Finite inputs whose results overflow the dtype: refused, not NaN or inf.
        big = np.finfo(dtype).max / 4
        with np.errstate(all="ignore"):
            for apply, n, name in ((op.matvec, 60, "x"), (op.rmatvec, 24, "y")):
                with pytest.raises(ValueError) as e:
                    apply(np.full(n, big, dtype=dtype))
                one_line(e, name, "overflow")
    # float64 values of 1e308: overflowing the float32 operator's dtype, or the float64 result.
    op32 = rdlidar.RdOperator(pulse, codes, 5, dtype=np.float32)
    op64 = rdlidar.RdOperator(pulse, codes, 5, dtype=np.float64)
    with np.errstate(all="ignore"):
        for op in (op32, op64):
            with pytest.raises(ValueError) as e:
                op.matvec(np.full(60, 1e308))
            one_line(e, "x", "overflow")
            with pytest.raises(ValueError) as e:
                op.rmatvec(np.full(24, 1e308))
            one_line(e, "y", "overflow")
    # Large values whose results stay finite are fine.
    assert np.isfinite(op64.matvec(np.full(60, 1e300))).all()


def test_d10_refusing_an_overflow_into_float32_raises_no_numpy_warning(problem):
    # Found testing D10: the float64 -> float32 conversion of an x of 1e308 emits numpy's
    # "RuntimeWarning: overflow encountered in cast" before the ValueError; with warnings as
    # errors (pytest -W error, a common setting) the caller gets that RuntimeWarning instead of
    # the ValueError naming x.
    pulse, codes = problem
    op32 = rdlidar.RdOperator(pulse, codes, 5, dtype=np.float32)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError) as e:
            op32.matvec(np.full(60, 1e308))
        one_line(e, "x", "overflow")
        with pytest.raises(ValueError) as e:
            op32.adjoint(np.full(24, 1e308))
        one_line(e, "y", "overflow")
        with pytest.raises(ValueError) as e:
            rdlidar.reconstruct(op32, None, np.full(24, 1e308), None)
        one_line(e, "meas", "overflow")


# D11 ------------------------------------------------------------------------------------------


def test_d11_out_of_range_integers_are_value_errors_and_wrong_types_type_errors(problem, op):
    pulse, codes = problem
    value_errors = [
        (lambda: rdlidar.simulate(size=(-8, 8, 6), pulse_len=10), "size"),
        (lambda: rdlidar.simulate(size=(8, 8, 6), pulse_len=-1), "pulse_len"),
        (lambda: rdlidar.simulate(size=(8, 8, 6), pulse_len=10, seed=2**64), "seed"),
        (lambda: rdlidar.simulate(size=(8, 8, 6), pulse_len=10, adcs=-2), "adcs"),
        (lambda: rdlidar.simulate(size=(8, 8, 6), pulse_len=10, tiles=(-1, 2)), "tiles"),
        (lambda: rdlidar.dot_test(op, seed=-1), "seed"),
        (lambda: rdlidar.dot_test(op, seed=2**64), "seed"),
        (lambda: rdlidar.RdOperator(pulse, codes, depth_bins=2**64), "depth_bins"),
        (lambda: rdlidar.RdOperator(pulse, codes, depth_bins=-5), "depth_bins"),
        (lambda: rdlidar.RdOperator(pulse, codes, 5, tiles=(2**64, 1)), "tiles"),
        (lambda: rdlidar.reconstruct(pulse, codes, np.zeros(24), 5, max_iter=2**64),
         "max_iter"),
        (lambda: rdlidar.reconstruct(pulse, codes, np.zeros(24), 5, max_iter=-1), "max_iter"),
        (lambda: rdlidar.reconstruct(pulse, codes, np.zeros(24), 5, seed=2**64), "seed"),
        (lambda: rdlidar.fista(op, np.zeros(24), 0.1, niter=2**64), "niter"),
    ]
    for call, name in value_errors:
        with pytest.raises(ValueError) as e:
            call()
        assert not isinstance(e.value, OverflowError), name
        one_line(e, name)
    type_errors = [
        (lambda: rdlidar.fista(op, np.zeros(24), lam="x"), "lam"),
        (lambda: rdlidar.fista(op, np.zeros(24), lam=None), "lam"),
        (lambda: rdlidar.fista(op, np.zeros(24), 0.1, step="x"), "step"),
        (lambda: rdlidar.fista(op, np.zeros(24), 0.1, tol="1e-3"), "tol"),
        (lambda: rdlidar.dot_test(op, tolerance="x"), "tolerance"),
        (lambda: rdlidar.metrics(np.zeros((2, 2, 3)), np.zeros((2, 2, 3)), tau_s="200ps"),
         "tau_s"),
        (lambda: rdlidar.metrics(np.zeros((2, 2, 3)), np.zeros((2, 2, 3)), tau_s=True), "tau_s"),
        (lambda: rdlidar.simulate(size=(8, 8, 6), pulse_len=10, snr_db="20"), "snr_db"),
        (lambda: rdlidar.simulate(size=(8, 8, 6), pulse_len=10, aperture="half"), "aperture"),
    ]
    for call, name in type_errors:
        with pytest.raises(TypeError) as e:
            call()
        one_line(e, name)


# D12 ------------------------------------------------------------------------------------------


def test_d12_no_silent_coercion_of_integers(problem, op):
    pulse, codes = problem
    type_errors = [
        (lambda: rdlidar.simulate(size=(8.7, 8, 6), pulse_len=10), "size"),
        (lambda: rdlidar.simulate(size=(8.0, 8, 6), pulse_len=10), "size"),
        (lambda: rdlidar.simulate(size=("8", "8", "6"), pulse_len=10), "size"),
        (lambda: rdlidar.simulate(size=(True, 8, 6), pulse_len=10), "size"),
        (lambda: rdlidar.simulate(size=(8, 8, 6), pulse_len="100"), "pulse_len"),
        (lambda: rdlidar.simulate(size=(8, 8, 6), pulse_len=100.0), "pulse_len"),
        (lambda: rdlidar.simulate(size=(8, 8, 6), pulse_len=10, seed=1.5), "seed"),
        (lambda: rdlidar.simulate(size=(8, 8, 6), pulse_len=10, seed="1"), "seed"),
        (lambda: rdlidar.simulate(size=(8, 8, 6), pulse_len=10, adcs=2.0), "adcs"),
        (lambda: rdlidar.simulate(size=(8, 8, 6), pulse_len=10, tiles=(2.5, 2)), "tiles"),
        (lambda: rdlidar.dot_test(op, seed=1.7), "seed"),
        (lambda: rdlidar.dot_test(op, seed="1"), "seed"),
        (lambda: rdlidar.RdOperator(pulse, codes, np.float64(5)), "depth_bins"),
        (lambda: rdlidar.reconstruct(pulse, codes, np.zeros(24), 5, max_iter=3.0), "max_iter"),
        (lambda: rdlidar.reconstruct(pulse, codes, np.zeros(24), 5, seed=0.5), "seed"),
        (lambda: rdlidar.fista(op, np.zeros(24), 0.1, niter=10.0), "niter"),
    ]
    for call, name in type_errors:
        with pytest.raises(TypeError) as e:
            call()
        one_line(e, name)
    # NumPy integers are integers.
    i = np.int64
    sim = rdlidar.simulate(size=(i(8), np.int32(8), np.uint8(6)), pulse_len=i(50),
                           seed=np.uint64(3), adcs=np.int16(2))
    same = rdlidar.simulate(size=(8, 8, 6), pulse_len=50, seed=3, adcs=2)
    assert np.array_equal(sim.meas, same.meas) and sim.meta == same.meta
    tiled = rdlidar.simulate(size=(8, 8, 6), pulse_len=50, tiles=(i(4), np.uint32(4)))
    assert tiled.tiles == (4, 4)
    other = rdlidar.RdOperator(pulse, codes, i(5), tiles=(i(2), i(2)))
    assert other.tiles == (2, 2) and other.scene_shape == (3, 4, 5)
    assert rdlidar.dot_test(op, seed=i(4))["passed"]
    _, _, report = rdlidar.reconstruct(pulse, codes, np.ones(24), i(5), solver="cgls",
                                       max_iter=i(2), seed=np.uint64(1))
    assert report["iterations"] <= 2
    _, report = rdlidar.fista(op, np.ones(24), np.float32(0.1), niter=i(3))
    assert report["iterations"] == 3


# The inputs of the architectures ---------------------------------------------------------------


def test_codes_of_the_wrong_dimensions_or_tiles_are_refused(problem):
    pulse, codes = problem
    for bad in (codes[None, None], np.packbits(codes > 0, axis=-1)[None, None], codes[0],
                np.int8(1)):
        with pytest.raises(ValueError) as e:
            rdlidar.RdOperator(pulse, bad, 5)
        one_line(e, "codes", "4-D")
    for bad in ((0, 2), (2, 0)):
        with pytest.raises(ValueError) as e:
            rdlidar.RdOperator(pulse, codes, 5, tiles=bad)
        one_line(e, "tiles")
        with pytest.raises(ValueError) as e:
            rdlidar.reconstruct(pulse, codes, np.zeros((1, 24)), 5, tiles=bad)
        one_line(e, "tiles")
    for bad in ("2x2", b"2x2", (2,), (2, 2, 2), 2, 2.5):
        with pytest.raises(TypeError) as e:
            rdlidar.RdOperator(pulse, codes, 5, tiles=bad)
        one_line(e, "tiles")
    assert rdlidar.RdOperator(pulse, codes, 5, tiles=[2, 2]).tiles == (2, 2)
    assert rdlidar.RdOperator(pulse, codes, 5, tiles=np.array([2, 2])).tiles == (2, 2)
    # Tiles of 4-D codes of 2 sets: two architectures at once.
    with pytest.raises(ValueError) as e:
        rdlidar.RdOperator(pulse, np.stack([codes, -codes]), 5, tiles=(2, 2))
    one_line(e, "tiles", "2 code sets")


def test_sets_and_mappings_are_not_sequences_of_integers(problem):
    # Found testing D12 and the tiles: tiles=(A, B) and size=(M, N, K_s) take any object of the
    # right len, so a mapping of two keys raises a bare KeyError: 0, a set of two an unnamed
    # "'set' object is not subscriptable", and a set of three sizes is silently read in the
    # set's iteration order.
    pulse, codes = problem
    for bad in ({"rows": 2, "cols": 2}, {2, 3}):
        with pytest.raises(TypeError) as e:
            rdlidar.RdOperator(pulse, codes, 5, tiles=bad)
        one_line(e, "tiles")
        with pytest.raises(TypeError) as e:
            rdlidar.simulate(size=(8, 8, 6), pulse_len=10, tiles=bad)
        one_line(e, "tiles")
    for bad in ({8, 9, 6}, {"m": 8, "n": 8, "ks": 6}):
        with pytest.raises(TypeError) as e:
            rdlidar.simulate(size=bad, pulse_len=10)
        one_line(e, "size")


def test_measurements_of_the_wrong_shape_for_the_architecture_are_refused():
    multi = rdlidar.simulate("paper", size=(8, 8, 6), pulse_len=150, seed=5, adcs=3)
    op = multi.operator()
    k = 155
    for bad in (multi.meas[:2], multi.meas[0], multi.meas.T, multi.meas[None]):
        with pytest.raises(ValueError) as e:
            rdlidar.reconstruct(multi.pulse, multi.codes, bad, 6)
        one_line(e, "meas", f"(3, {k})")
        with pytest.raises(ValueError) as e:
            rdlidar.fista(op, bad, 0.1)
        one_line(e, "meas", f"(3, {k})")
        with pytest.raises(ValueError) as e:
            op.adjoint(bad)
        one_line(e, "y", f"(3, {k})")
    tiled = rdlidar.simulate("paper", size=(8, 8, 6), pulse_len=150, seed=5, tiles=(3, 5))
    for bad, tiles, want in ((tiled.meas[:4], (3, 5), f"(6, {k})"),
                             (tiled.meas, None, f"({k},)"),
                             (tiled.meas, (4, 4), f"(4, {k})")):
        with pytest.raises(ValueError) as e:
            rdlidar.reconstruct(tiled.pulse, tiled.codes, bad, 6, tiles=tiles)
        one_line(e, "meas", want)


def test_seeded_and_file_codes_that_disagree_are_refused(tmp_path, problem):
    pulse, codes = problem
    tiled = rdlidar.simulate("paper", size=(8, 8, 6), pulse_len=150, seed=5, tiles=(3, 5),
                             codes_format="seed", out=tmp_path / "tiled")
    meta = tmp_path / "tiled" / "meta.json"
    for call in (lambda: rdlidar.RdOperator(tiled.pulse, meta, 6, tiles=(4, 4)),
                 lambda: rdlidar.reconstruct(tiled.pulse, meta, tiled.meas, 6, tiles=(4, 4))):
        with pytest.raises(ValueError) as e:
            call()
        one_line(e, "meta.json", "tiles", "3x5", "4x4")
    assert rdlidar.RdOperator(tiled.pulse, meta, 6, tiles=(3, 5)).tiles == (3, 5)
    # stream_codes streams seeded codes only.
    with pytest.raises(ValueError) as e:
        rdlidar.RdOperator(pulse, codes, 5, stream_codes=True)
    one_line(e, "stream_codes")
    with pytest.raises(ValueError) as e:
        rdlidar.reconstruct(pulse, codes, np.zeros(24), 5, stream_codes=True)
    one_line(e, "stream_codes")
    # A path that does not exist: the message names it.
    missing = tmp_path / "nowhere" / "meta.json"
    for call in (lambda: rdlidar.RdOperator(pulse, missing, 5),
                 lambda: rdlidar.RdOperator(pulse, os.fspath(tmp_path / "absent.npy"), 5),
                 lambda: rdlidar.reconstruct(pulse, missing, np.zeros(24), 5)):
        with pytest.raises(ValueError) as e:
            call()
        one_line(e)
        assert ("nowhere" in str(e.value)) or ("absent.npy" in str(e.value)), str(e.value)
    # The contents of meta.json instead of its path.
    with open(meta) as f:
        contents = json.load(f)
    with pytest.raises(TypeError) as e:
        rdlidar.RdOperator(tiled.pulse, contents, 6)
    one_line(e, "codes", "path")


def test_bad_architecture_requests_of_simulate_are_refused():
    base = dict(size=(8, 8, 6), pulse_len=50)
    value_errors = [
        (dict(codes_format="zip"), "codes_format"),
        (dict(adcs=2, tiles=(2, 2)), "tiles"),
        (dict(adcs=2, aperture=0.5), "aperture"),
        (dict(tiles=(2, 2), aperture=0.5), "aperture"),
        (dict(adcs=0), "adcs"),
        (dict(adcs=5000), "adcs"),
        (dict(tiles=(0, 2)), "tiles"),
        (dict(aperture=0.0), "aperture"),
        (dict(aperture=1.5), "aperture"),
        (dict(aperture=float("nan")), "aperture"),
        (dict(aperture=0.5, codes_format="packed"), "codes_format"),
        (dict(aperture=0.5, codes_format="seed"), "codes_format"),
        (dict(ternary_zero_prob=0.3, codes_format="seed"), "codes_format"),
        (dict(ternary_zero_prob=0.3, codes_format="packed"), "codes_format"),
    ]
    for kwargs, name in value_errors:
        with pytest.raises(ValueError) as e:
            rdlidar.simulate(**base, **kwargs)
        one_line(e, name)
    for kwargs, name in ((dict(tiles="2x2"), "tiles"), (dict(codes_format=8), "codes_format"),
                         (dict(out=3), "out")):
        with pytest.raises(TypeError) as e:
            rdlidar.simulate(**base, **kwargs)
        one_line(e, name)


def test_simulate_out_is_refused_when_not_empty_unless_forced(tmp_path):
    base = dict(size=(4, 4, 3), pulse_len=20)
    (tmp_path / "keep.txt").write_text("mine")
    with pytest.raises(ValueError) as e:
        rdlidar.simulate(**base, out=tmp_path)
    one_line(e, "out", "force=True")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.txt"]
    sim = rdlidar.simulate(**base, out=tmp_path, force=True)
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["codes.npy", "keep.txt", "meas.npy", "meta.json", "pulse.npy", "scene.npy"]
    assert sim.files == str(tmp_path)


def test_one_code_set_with_a_set_axis_reads_as_the_command_line_reads_it(problem):
    pulse, codes = problem
    one = codes[None]
    op = rdlidar.RdOperator(pulse, one, 5, dtype=np.float64)
    assert op.architecture == "multi_adc" and op.rows == 1 and op.meas_shape == (1, 24)
    plain = rdlidar.RdOperator(pulse, codes, 5, dtype=np.float64)
    x = np.random.default_rng(3).random(60)
    assert np.array_equal(op.matvec(x), plain.matvec(x))
    with pytest.raises(ValueError) as e:
        rdlidar.RdOperator(pulse, one, 5, tiles=(2, 2))
    one_line(e, "codes", "(tiles)", "2x2")
    with pytest.raises(TypeError) as e:
        rdlidar.RdOperator(pulse, codes > 0, 5)
    one_line(e, "codes", "bool")


def test_simulate_out_is_checked_before_simulating(tmp_path):
    base = dict(size=(4, 4, 3), pulse_len=20)
    with pytest.raises(ValueError) as e:
        rdlidar.simulate(**base, out=tmp_path / "no" / "such")
    one_line(e, "out", "parent")
    (tmp_path / "file").write_text("x")
    with pytest.raises(ValueError) as e:
        rdlidar.simulate(**base, out=tmp_path / "file")
    one_line(e, "out", "not a folder")
