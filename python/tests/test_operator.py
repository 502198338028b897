"""The operator from Python: agreement with a numpy model, SciPy's and PyLops' interfaces,
their dot tests and solvers, and the GIL released during an application."""

import threading
import time

import numpy as np
import pytest
import scipy.sparse.linalg as spla

import rdlidar
from conftest import numpy_adjoint, numpy_forward, random_problem

SIZES = [(3, 5, 7, 13), (5, 2, 4, 9), (1, 1, 1, 1), (2, 3, 65, 11)]
TOL = {np.float32: 2e-5, np.float64: 1e-12}


def rel(a, b):
    return np.linalg.norm(np.ravel(a) - np.ravel(b)) / max(np.linalg.norm(np.ravel(b)), 1e-300)


@pytest.mark.parametrize("size", SIZES)
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("form", ["int8", "packed", "ternary"])
def test_the_operator_is_the_numpy_model(size, dtype, form):
    m, n, ks, kp = size
    pulse, codes = random_problem(m, n, ks, kp, seed=sum(size), ternary=form == "ternary")
    given = np.packbits(codes > 0, axis=-1) if form == "packed" else codes
    op = rdlidar.RdOperator(pulse, given, ks, dtype=dtype)
    k = kp + ks - 1
    assert op.shape == (k, m * n * ks)
    assert op.dtype == np.dtype(dtype)
    assert op.scene_shape == (m, n, ks)
    rng = np.random.default_rng(7)
    x = rng.standard_normal((m, n, ks)).astype(dtype)
    y = rng.standard_normal(k).astype(dtype)
    want_y = numpy_forward(pulse, codes, x)
    want_x = numpy_adjoint(pulse, codes, y.astype(np.float64), ks)
    # Scene-shaped and flat, through every interface.
    for got in (op.forward(x), op.forward(x.ravel()), op.matvec(x.ravel()), op @ x.ravel()):
        assert got.dtype == np.dtype(dtype) and got.shape == (k,)
        assert rel(got, want_y) < TOL[dtype]
    assert op.matvec(x.reshape(-1, 1)).shape == (k, 1)
    got = op.adjoint(y)
    assert got.shape == (m, n, ks) and got.dtype == np.dtype(dtype)
    assert rel(got, want_x) < TOL[dtype]
    assert rel(op.rmatvec(y), want_x) < TOL[dtype]
    assert rel(op.H @ y, want_x) < TOL[dtype]
    assert rel(op.T.matvec(y), want_x) < TOL[dtype]
    assert rel(op.H.H @ x.ravel(), want_y) < TOL[dtype]
    # Several columns at once.
    X = rng.standard_normal((m * n * ks, 3))
    Y = op.matmat(X)
    assert Y.shape == (k, 3)
    for j in range(3):
        assert rel(Y[:, j], numpy_forward(pulse, codes, X[:, j].reshape(m, n, ks))) < TOL[dtype]
    Z = op.H.matmat(rng.standard_normal((k, 2)))
    assert Z.shape == (m * n * ks, 2)


def test_arrays_of_other_layouts_and_dtypes_are_converted():
    pulse, codes = random_problem(4, 3, 6, 10, seed=1)
    op = rdlidar.RdOperator(pulse, codes, 6, dtype=np.float64)
    rng = np.random.default_rng(2)
    x = rng.standard_normal((4, 3, 6))
    want = op.forward(x)
    # Fortran order, a strided view, float32 and integer scenes, int64 and float codes.
    assert np.allclose(op.forward(np.asfortranarray(x)), want, rtol=0, atol=1e-12)
    big = np.zeros((8, 3, 6))
    big[::2] = x
    assert np.allclose(op.forward(big[::2]), want, rtol=0, atol=1e-12)
    assert rel(op.forward(x.astype(np.float32)), want) < 1e-6
    xi = np.ones((4, 3, 6), dtype=np.int64)
    assert np.allclose(op.forward(xi), op.forward(np.ones((4, 3, 6))))
    for c in (codes.astype(np.int64), codes.astype(np.float64), np.asfortranarray(codes)):
        other = rdlidar.RdOperator(pulse, c, 6, dtype=np.float64)
        assert np.array_equal(other.forward(x), want)
    # A list pulse.
    assert np.array_equal(rdlidar.RdOperator(list(pulse), codes, 6, dtype=np.float64).forward(x), want)


@pytest.mark.parametrize("dtype,rtol", [(np.float32, 1e-4), (np.float64, 1e-10)])
def test_pylops_dottest_passes(dtype, rtol):
    pylops = pytest.importorskip("pylops")
    pulse, codes = random_problem(6, 5, 8, 40, seed=3)
    for given in (codes, np.packbits(codes > 0, axis=-1)):
        op = rdlidar.RdOperator(pulse, given, 8, dtype=dtype)
        Op = pylops.aslinearoperator(op)
        assert pylops.utils.dottest(Op, *op.shape, rtol=rtol, raiseerror=True)
    r = rdlidar.dot_test(op, seed=4)
    assert r["passed"] and r["gap"] < (1e-5 if dtype == np.float32 else 1e-12)


def test_scipy_least_squares_recovers_a_scene_in_the_redundant_regime():
    m, n, ks, kp = 2, 2, 4, 200
    pulse, codes = random_problem(m, n, ks, kp, seed=5)
    op = rdlidar.RdOperator(pulse, codes, ks, dtype=np.float64)
    x = np.random.default_rng(6).standard_normal(m * n * ks)
    y = op @ x
    sol = spla.lsqr(op, y, atol=1e-14, btol=1e-14, iter_lim=500)[0]
    assert rel(sol, x) < 1e-8


def test_pylops_solver_runs_on_the_operator():
    pylops = pytest.importorskip("pylops")
    m, n, ks, kp = 2, 3, 4, 150
    pulse, codes = random_problem(m, n, ks, kp, seed=8)
    op = rdlidar.RdOperator(pulse, codes, ks, dtype=np.float64)
    Op = pylops.aslinearoperator(op)
    x = np.random.default_rng(9).standard_normal(m * n * ks)
    y = Op @ x
    sol = pylops.optimization.basic.cgls(Op, y, x0=np.zeros_like(x), niter=200, tol=1e-14)[0]
    assert rel(sol, x) < 1e-8


def test_the_gil_is_released_during_an_application():
    # A Python thread notes the longest pause between its steps while one adjoint runs: were
    # the GIL held, it would stall for the whole application. The application must be long
    # against the scheduler's time slices, so the pulse grows until one adjoint of a 128x128x40
    # array takes a tenth of a second (K_p 20 000 sufficed before the kernels got faster).
    m, n, ks = 128, 128, 40
    rng = np.random.default_rng(10)
    for kp in (20000, 40000, 80000, 160000):
        pulse = (rng.random(kp) < 0.5).astype(np.float64)
        k = kp + ks - 1
        packed = rng.integers(0, 256, size=(m, n, (k + 7) // 8), dtype=np.uint8)
        packed[..., -1] &= np.uint8((0xFF << (8 * packed.shape[-1] - k)) & 0xFF)
        op = rdlidar.RdOperator(pulse, packed, ks, dtype=np.float64)
        y = rng.standard_normal(k)
        op.adjoint(y)  # warm up
        t0 = time.perf_counter()
        op.adjoint(y)
        if time.perf_counter() - t0 > 0.1:
            break
    longest = [0.0]
    steps = [0]
    stop = threading.Event()
    running = threading.Event()

    def watch():
        last = time.perf_counter()
        while not stop.is_set():
            now = time.perf_counter()
            longest[0] = max(longest[0], now - last)
            last = now
            steps[0] += 1
            running.set()

    t = threading.Thread(target=watch)
    t.start()
    running.wait()
    time.sleep(0.02)
    longest[0] = 0.0
    t0 = time.perf_counter()
    op.adjoint(y)
    elapsed = time.perf_counter() - t0
    stop.set()
    t.join()
    assert elapsed > 0.05, f"the application was too quick to tell ({elapsed:.3f} s)"
    assert longest[0] < 0.5 * elapsed, (
        f"the other thread stalled for {longest[0]:.3f} s of a {elapsed:.3f} s application"
    )


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_fista_iterates_are_pylops_fista_iterates(dtype):
    pylops = pytest.importorskip("pylops")
    sim = rdlidar.simulate("paper", size=(8, 6, 10), pulse_len=400, seed=11, dtype=dtype)
    op = sim.operator()
    Op = pylops.aslinearoperator(op)
    alpha = 1.0 / (1.05 * rdlidar_norm2(op))
    eps = 0.02 * float(np.abs(op.H @ sim.meas).max())
    for niter in (1, 5, 60):
        x_pylops = pylops.optimization.sparsity.fista(
            Op, sim.meas, niter=niter, eps=eps, alpha=alpha, tol=0.0, show=False
        )[0]
        x, report = rdlidar.fista(op, sim.meas, lam=eps / 2, step=alpha, niter=niter)
        assert report["iterations"] == niter
        gap = np.linalg.norm(x - x_pylops) / np.linalg.norm(x_pylops)
        assert gap < (1e-5 if dtype == np.float32 else 1e-12), (niter, gap)


def rdlidar_norm2(op):
    """||A||^2 by power iteration in float64."""
    v = np.random.default_rng(0).standard_normal(op.shape[1])
    for _ in range(200):
        w = op.H @ (op @ v)
        lam = np.linalg.norm(w)
        v = w / lam
    return lam


def test_rdlidar_isa_caps_the_kernels_of_new_operators():
    """RDLIDAR_ISA, read when an operator is built: generic gives the generic kernels and the
    same products; a value that names no instruction set is refused, naming the variable."""
    import subprocess
    import sys
    import textwrap

    script = textwrap.dedent(
        """
        import numpy as np, rdlidar
        rng = np.random.default_rng(0)
        codes = np.where(rng.random((3, 4, 40)) < 0.5, 1, -1).astype(np.int8)
        op = rdlidar.RdOperator(rng.random(33) + 0.1, codes, 8, dtype=np.float64)
        x = np.linspace(-1.0, 1.0, op.shape[1])
        print(op.isa, repr(float((op @ x) @ np.arange(op.shape[0]))))
        """
    )

    def run(isa):
        env = dict(__import__("os").environ, RDLIDAR_ISA=isa)
        return subprocess.run(
            [sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=120
        )

    generic, native = run("generic"), run("native")
    assert generic.returncode == 0 and native.returncode == 0, generic.stderr + native.stderr
    g_isa, g_value = generic.stdout.split()
    n_isa, n_value = native.stdout.split()
    assert g_isa == "generic"
    assert n_isa in ("generic", "avx2+fma", "avx512")
    assert abs(float(g_value) - float(n_value)) <= 1e-12 * abs(float(n_value))
    bad = run("sse9")
    assert bad.returncode != 0
    assert "RDLIDAR_ISA" in bad.stderr and "sse9" in bad.stderr
