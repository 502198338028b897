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


# A bad-input campaign (B01 ... B08 of tests/cli_bad_input.rs): the same rules as the command
# line's.


@pytest.mark.parametrize("value", ["5XB", "-1", "lots", "1e30", "-5MB", "5 M B"])
def test_b01_an_invalid_memory_limit_is_refused_not_ignored(monkeypatch, value):
    monkeypatch.setenv("RDLIDAR_MEMORY_LIMIT", value)
    with pytest.raises(ValueError) as e:
        rdlidar.simulate(size=(4, 4, 4), pulse_len=50)
    one_line(e, "RDLIDAR_MEMORY_LIMIT", repr(value).replace("'", '"'))


@pytest.mark.parametrize("value,shown", [("5MB", "5 MB"), ("5MiB", "5.24 MB"), ("5M", "5.24 MB")])
def test_b01_memory_limits_with_units_are_applied(monkeypatch, value, shown):
    monkeypatch.setenv("RDLIDAR_MEMORY_LIMIT", value)
    with pytest.raises(MemoryError) as e:
        rdlidar.simulate(size=(200, 200, 40), pulse_len=100)  # a scene of 12.8 MB
    one_line(e, f"the {shown} of memory")
    monkeypatch.setenv("RDLIDAR_MEMORY_LIMIT", "1G")
    assert rdlidar.simulate(size=(4, 4, 4), pulse_len=50).meas.shape == (53,)


def test_b02_numbers_of_any_size_are_echoed_in_a_few_characters():
    # clipped=1e-300 gave a message of 763 characters, the level in full decimal.
    sim = rdlidar.simulate(size=(8, 8, 6), pulse_len=100, seed=3)
    cases = [
        (lambda: rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, 6, solver="cgls",
                                     clipped=1e-300), ("clipped", "1e-300")),
        (lambda: rdlidar.simulate(size=(8, 8, 6), pulse_len=100, snr_db=-1e308),
         ("snr_db", "-1e308")),
    ]
    for call, needles in cases:
        with pytest.raises(ValueError) as e:
            call()
        one_line(e, *needles)
        msg = str(e.value)
        assert len(msg) < 300 and "00000000" not in msg, msg


def test_b03_a_full_scale_beyond_float32_names_full_scale(tmp_path):
    out = tmp_path / "run"
    with pytest.raises(ValueError) as e:
        rdlidar.simulate(size=(8, 8, 6), pulse_len=100, adc_bits=8, full_scale=1e300,
                         dtype=np.float32, out=out)
    one_line(e, "full_scale", "1e300", "f32", "f64")
    assert not out.exists()
    sim = rdlidar.simulate(size=(8, 8, 6), pulse_len=100, adc_bits=8, full_scale=1e300)
    assert np.isfinite(sim.meas).all()


def test_b04_a_0d_pulse_is_refused_as_on_the_command_line(problem):
    _, codes = problem
    for p in (np.float64(1.0), np.array(1.0), 1.0):
        with pytest.raises(ValueError) as e:
            rdlidar.RdOperator(p, codes[..., :5], 5)  # K = 1 + 5 - 1
        one_line(e, "pulse", "1-D")
        with pytest.raises(ValueError) as e:
            rdlidar.reconstruct(p, codes[..., :5], np.zeros(5), 5)
        one_line(e, "pulse", "1-D")
