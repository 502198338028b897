"""Every bad input is a ValueError or TypeError with a one-line message naming the argument;
none crashes the interpreter."""

import numpy as np
import pytest

import rdlidar
from conftest import random_problem


def one_line(excinfo, *needles):
    msg = str(excinfo.value)
    assert "\n" not in msg, msg
    for n in needles:
        assert n in msg, msg


@pytest.fixture
def problem():
    return random_problem(3, 4, 5, 20, seed=1)


def test_bad_codes(problem):
    pulse, codes = problem
    with pytest.raises(ValueError) as e:
        rdlidar.RdOperator(pulse, codes[..., :-1], 5)
    one_line(e, "codes", "K = K_p + K_s - 1 = 24")
    bad = codes.astype(np.int64)
    bad[1, 2, 3] = 2
    with pytest.raises(ValueError) as e:
        rdlidar.RdOperator(pulse, bad, 5)
    one_line(e, "codes", "(1, 2, 3)")
    with pytest.raises(ValueError) as e:
        rdlidar.RdOperator(pulse, codes.reshape(12, 24), 5)
    one_line(e, "codes", "3-D")
    with pytest.raises(TypeError) as e:
        rdlidar.RdOperator(pulse, codes.astype(np.complex64), 5)
    one_line(e, "codes")
    with pytest.raises(TypeError) as e:
        rdlidar.RdOperator(pulse, codes.astype(str), 5)
    one_line(e, "codes")
    packed = np.packbits(codes > 0, axis=-1)
    with pytest.raises(ValueError) as e:
        rdlidar.RdOperator(pulse, packed[..., :-1], 5)
    one_line(e, "codes", "bytes per pixel")
    padded = packed.copy()
    padded[2, 1, -1] |= 1  # a pad bit: 24 samples use 3 full bytes, so force 25 samples
    with pytest.raises(ValueError) as e:
        rdlidar.RdOperator(np.ones(21), padded, 5)
    one_line(e, "codes")


def test_bad_pulse_and_depth_bins(problem):
    pulse, codes = problem
    for p in (np.array([]), pulse.reshape(4, 5)):
        with pytest.raises(ValueError) as e:
            rdlidar.RdOperator(p, codes, 5)
        one_line(e, "pulse")
    nan = pulse.copy()
    nan[3] = np.nan
    with pytest.raises(ValueError) as e:
        rdlidar.RdOperator(nan, codes, 5)
    one_line(e, "pulse", "3")
    with pytest.raises(ValueError) as e:
        rdlidar.RdOperator(np.full(20, 1e39), codes, 5, dtype=np.float32)
    one_line(e, "pulse")
    with pytest.raises(TypeError):
        rdlidar.RdOperator(pulse.astype(np.complex128), codes, 5)
    with pytest.raises(ValueError) as e:
        rdlidar.RdOperator(pulse, codes, 0)
    one_line(e, "depth_bins")
    with pytest.raises(TypeError) as e:
        rdlidar.RdOperator(pulse, codes, 5.0)
    one_line(e, "depth_bins")
    with pytest.raises(TypeError) as e:
        rdlidar.RdOperator(pulse, codes, 5, dtype=np.int32)
    one_line(e, "dtype")


def test_bad_vectors(problem):
    pulse, codes = problem
    op = rdlidar.RdOperator(pulse, codes, 5)
    with pytest.raises(ValueError) as e:
        op.forward(np.zeros(10))
    one_line(e, "x", "(3, 4, 5)")
    with pytest.raises(ValueError) as e:
        op.adjoint(np.zeros(23))
    one_line(e, "y", "(24,)")
    with pytest.raises(ValueError):
        op.matvec(np.zeros(59))
    with pytest.raises(TypeError) as e:
        op.forward(np.zeros((3, 4, 5), dtype=complex))
    one_line(e, "complex")
    with pytest.raises(TypeError):
        op._core.forward(np.zeros(60, dtype=np.float64))  # the core takes its own dtype only
    with pytest.raises(ValueError):
        op._core.forward(np.zeros(59, dtype=np.float32))
    with pytest.raises(TypeError):
        rdlidar.dot_test("not an operator")
    with pytest.raises(ValueError) as e:
        rdlidar.dot_test(op, tolerance=-1.0)
    one_line(e, "tolerance")


def test_bad_reconstruction_requests(problem):
    pulse, codes = problem
    y = np.zeros(24)
    with pytest.raises(ValueError) as e:
        rdlidar.reconstruct(pulse, codes, y, 5, solver="lasso")
    one_line(e, "solver", "lasso")
    with pytest.raises(ValueError) as e:
        rdlidar.reconstruct(pulse, codes, np.zeros(23), 5)
    one_line(e, "meas", "(24,)")
    bad = y.copy()
    bad[5] = np.inf
    with pytest.raises(ValueError) as e:
        rdlidar.reconstruct(pulse, codes, bad, 5)
    one_line(e, "meas", "5")
    with pytest.raises(ValueError) as e:
        rdlidar.reconstruct(pulse, codes, y, 5, max_iter=0)
    one_line(e, "max_iter")
    with pytest.raises(TypeError):
        rdlidar.reconstruct(pulse, codes, y, 5, max_iter=2.5)
    with pytest.raises(TypeError):
        rdlidar.reconstruct(pulse, codes, y, 5, callback=3)
    with pytest.raises(TypeError):
        rdlidar.reconstruct(pulse, codes, y, 5, solver=3)
    with pytest.raises(ValueError) as e:
        rdlidar.reconstruct(pulse, codes, y, 5, seed=-3)
    one_line(e, "seed")
    plain = rdlidar.RdOperator(pulse, codes, 5)
    for kwargs, needle in ((dict(lam=-1.0), "lam"), (dict(lam=0.1, step=0.0), "step"),
                           (dict(lam=0.1, niter=0), "niter")):
        with pytest.raises(ValueError) as e:
            rdlidar.fista(plain, y, **kwargs)
        one_line(e, needle)
    op = rdlidar.RdOperator(pulse, codes, 5, debiased=True)
    with pytest.raises(ValueError) as e:
        rdlidar.reconstruct(op, None, y, None)
    one_line(e, "debiased")


def test_bad_simulations_and_metrics():
    cases = [
        (dict(scene="cube"), ValueError, "scene"),
        (dict(size=(0, 4, 4)), ValueError, "size"),
        (dict(pulse_len=0), ValueError, "pulse_len"),
        (dict(scene="paper", lit_fraction=0.5), ValueError, "lit_fraction"),
        (dict(ternary_zero_prob=1.5), ValueError, "zero"),
        (dict(size=(100000, 100000, 100)), ValueError, "size"),
        (dict(size=(4096, 4096, 100), pulse_len=10**6), MemoryError, "memory"),
        (dict(size="big"), TypeError, "size"),
        (dict(seed=-1), ValueError, "seed"),
        (dict(seed=2**64), ValueError, "seed"),
        (dict(seed=1.5), TypeError, "seed"),
        (dict(snr_db=float("nan")), ValueError, "snr_db"),
        (dict(dtype=np.float16), TypeError, "dtype"),
    ]
    for kwargs, exc, needle in cases:
        args = dict(size=(4, 4, 4), pulse_len=50)
        args.update(kwargs)
        with pytest.raises(exc) as e:
            rdlidar.simulate(**args)
        one_line(e, needle)
    with pytest.raises(ValueError) as e:
        rdlidar.metrics(np.zeros((2, 2, 3)), np.zeros((2, 2, 4)))
    one_line(e, "estimate")
