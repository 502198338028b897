import os

import numpy as np
import pytest


def numpy_forward(pulse, codes, x):
    """y = sum over pixels of codes * (depth column convolved with the pulse), in float64."""
    m, n, ks = x.shape
    k = len(pulse) + ks - 1
    y = np.zeros(k)
    for i in range(m):
        for j in range(n):
            y += codes[i, j].astype(np.float64) * np.convolve(x[i, j].astype(np.float64), pulse)
    return y


def numpy_adjoint(pulse, codes, y, ks):
    """x[m, n, d] = sum_k codes[m, n, k] y[k] pulse[k - d], in float64."""
    m, n, _ = codes.shape
    x = np.zeros((m, n, ks))
    for i in range(m):
        for j in range(n):
            x[i, j] = np.correlate(codes[i, j].astype(np.float64) * y, pulse, mode="valid")
    return x


def random_problem(m, n, ks, kp, seed, ternary=False):
    rng = np.random.default_rng(seed)
    pulse = (rng.random(kp) < 0.5).astype(np.float64)
    pulse[0] = 1.0
    k = kp + ks - 1
    if ternary:
        codes = rng.integers(-1, 2, size=(m, n, k)).astype(np.int8)
    else:
        codes = np.where(rng.random((m, n, k)) < 0.5, -1, 1).astype(np.int8)
    return pulse, codes


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


@pytest.fixture(scope="session")
def rdlidar_bin():
    """The command line's binary, from RDLIDAR_BIN: a clear failure (never a skip) without it."""
    path = os.environ.get("RDLIDAR_BIN")
    if not path:
        pytest.fail(
            "RDLIDAR_BIN is not set: set it to the path of the rdlidar binary "
            "(e.g. RDLIDAR_BIN=$PWD/target/release/rdlidar after cargo build --release)",
            pytrace=False,
        )
    if not os.path.isfile(path) or not os.access(path, os.X_OK):
        pytest.fail(f"RDLIDAR_BIN={path!r} is not an executable file", pytrace=False)
    return path
