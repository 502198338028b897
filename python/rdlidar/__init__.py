"""rdlidar: compressive time-of-flight lidar by random demodulation.

The fast measurement operator of the random-demodulation lidar and its reconstruction methods,
from numpy, SciPy and PyLops. See docs/python.md in the repository.

Arrays
------
Inputs are converted with ``numpy.ascontiguousarray`` to the dtype each function documents
(the operator's dtype for scenes and measurements, float64 for pulses, int8 or packed uint8 for
codes): Fortran-ordered, strided and other-dtype real arrays are accepted and copied; complex
arrays, and arrays whose values do not fit (codes outside -1, 0, 1), are refused with
``TypeError`` or ``ValueError``. Errors of the library are ``ValueError`` with its one-line
message.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Optional, Tuple

import numpy as np
from scipy.sparse.linalg import LinearOperator

from . import _rdlidar
from ._rdlidar import __version__

__all__ = [
    "RdOperator",
    "Simulation",
    "simulate",
    "reconstruct",
    "fista",
    "dot_test",
    "metrics",
    "SOLVERS",
    "__version__",
]

#: The reconstruction methods ``reconstruct`` takes, as the command line names them.
SOLVERS: Tuple[str, ...] = tuple(_rdlidar.solvers())


def _real_dtype(dtype: Any) -> np.dtype:
    dt = np.dtype(dtype)
    if dt not in (np.dtype(np.float32), np.dtype(np.float64)):
        raise TypeError(f"dtype: rdlidar computes in float32 or float64, not {dt}")
    return dt


def _real_array(a: Any, dtype: np.dtype, what: str) -> np.ndarray:
    arr = np.asarray(a)
    if arr.dtype.kind == "c":
        raise TypeError(f"{what}: complex values are not supported (the operator is real)")
    if arr.dtype.kind not in "fiub":
        raise TypeError(f"{what}: expected a real numeric array, got dtype {arr.dtype}")
    return np.ascontiguousarray(arr, dtype=dtype)


def _codes_array(codes: Any) -> np.ndarray:
    c = np.asarray(codes)
    if c.ndim != 3:
        raise ValueError(
            f"codes: expected a 3-D array (M, N, K) or packed (M, N, ceil(K/8)), got shape {c.shape}"
        )
    if c.dtype == np.uint8:
        return np.ascontiguousarray(c)
    if c.dtype.kind == "c" or c.dtype.kind not in "fiub":
        raise TypeError(f"codes: expected int8 codes or packed uint8 bytes, got dtype {c.dtype}")
    if c.dtype != np.int8:
        bad = ~np.isin(c, (-1, 0, 1))
        if bad.any():
            idx = tuple(int(i) for i in np.argwhere(bad)[0])
            raise ValueError(f"codes: entry {idx} is {c[idx]!r}, not one of -1, 0, 1")
    return np.ascontiguousarray(c, dtype=np.int8)


class RdOperator(LinearOperator):
    """The random-demodulation lidar operator A (one ADC) as a SciPy ``LinearOperator``.

    ``y = A x`` with ``y[k] = sum_{m,n} s[m,n,k] (x[m,n,:] * p)[k]``: a scene ``x`` of
    M x N pixels and K_s depth bins (flattened in C order, depth fastest) to K = K_p + K_s - 1
    samples of one ADC.

    Parameters
    ----------
    pulse : array_like, shape (K_p,)
        The transmitted pulse (float; converted to ``dtype``).
    codes : array_like, shape (M, N, K) int8 or (M, N, ceil(K/8)) uint8
        Each pixel's codes in {-1, 0, +1}, or +-1 codes packed as ``np.packbits(S > 0, axis=-1)``
        writes them (uint8 arrays are always read as packed). Other integer or float arrays
        with values in {-1, 0, 1} are converted to int8.
    depth_bins : int
        K_s.
    dtype : numpy.float32 or numpy.float64
        The precision of the kernels (sums are accumulated in float64 either way).
    debiased : bool
        Use the zero-mean pulse p - mean(p): the adjoint is then the debiased backprojection.

    ``matvec``/``rmatvec``/``matmat``/``.H`` work as for any SciPy operator, so
    ``pylops.aslinearoperator(op)`` gives a PyLops operator. ``forward`` and ``adjoint`` also
    take and return (M, N, K_s) scenes. The kernels run without the GIL.
    """

    def __init__(self, pulse, codes, depth_bins, dtype=np.float32, debiased=False):
        dt = _real_dtype(dtype)
        p = _real_array(pulse, np.float64, "pulse")
        if p.ndim != 1:
            raise ValueError(f"pulse: expected a 1-D array (K_p,), got shape {p.shape}")
        if isinstance(depth_bins, bool) or not isinstance(depth_bins, (int, np.integer)):
            raise TypeError(f"depth_bins: expected an int, got {type(depth_bins).__name__}")
        if depth_bins < 1:
            raise ValueError(f"depth_bins: must be at least 1, got {depth_bins}")
        self._core = _rdlidar._Operator(
            p, _codes_array(codes), int(depth_bins), dt == np.float64, bool(debiased)
        )
        m, n, ks = self._core.geometry
        #: (M, N, K_s)
        self.scene_shape = (m, n, ks)
        #: K = K_p + K_s - 1
        self.samples = self._core.samples
        self.debiased = bool(debiased)
        super().__init__(dtype=dt, shape=(self.samples, m * n * ks))

    # SciPy's hooks ----------------------------------------------------------------------
    def _matvec(self, x):
        return self._core.forward(_real_array(x, self.dtype, "x").reshape(-1))

    def _rmatvec(self, y):
        return self._core.adjoint(_real_array(y, self.dtype, "y").reshape(-1))

    def _matmat(self, X):
        X = _real_array(X, self.dtype, "X")
        out = np.empty((self.shape[0], X.shape[1]), dtype=self.dtype)
        for j in range(X.shape[1]):
            out[:, j] = self._core.forward(np.ascontiguousarray(X[:, j]))
        return out

    def _rmatmat(self, Y):
        Y = _real_array(Y, self.dtype, "Y")
        out = np.empty((self.shape[1], Y.shape[1]), dtype=self.dtype)
        for j in range(Y.shape[1]):
            out[:, j] = self._core.adjoint(np.ascontiguousarray(Y[:, j]))
        return out

    def _adjoint(self):
        return _RdAdjoint(self)

    # Scene-shaped applications ----------------------------------------------------------
    def forward(self, x):
        """y = A x for a scene of shape (M, N, K_s) (or flat); returns (K,)."""
        x = _real_array(x, self.dtype, "x")
        if x.shape not in (self.scene_shape, (self.shape[1],)):
            raise ValueError(
                f"x: expected shape {self.scene_shape} or ({self.shape[1]},), got {x.shape}"
            )
        return self._core.forward(x.reshape(-1))

    def adjoint(self, y):
        """x = A^T y for measurements of shape (K,); returns (M, N, K_s)."""
        y = _real_array(y, self.dtype, "y")
        if y.shape != (self.samples,):
            raise ValueError(f"y: expected shape ({self.samples},), got {y.shape}")
        return self._core.adjoint(y).reshape(self.scene_shape)

    @property
    def pulse(self) -> np.ndarray:
        """The pulse the operator applies (zero-mean when debiased), float64."""
        return self._core.pulse

    @property
    def isa(self) -> str:
        """The instruction set the kernels run with."""
        return self._core.isa

    def __repr__(self):
        return f"<RdOperator: {self._core!r}>"


class _RdAdjoint(LinearOperator):
    """A^T of an ``RdOperator`` (what ``op.H`` and ``op.T`` give)."""

    def __init__(self, op: RdOperator):
        self._op = op
        super().__init__(dtype=op.dtype, shape=(op.shape[1], op.shape[0]))

    def _matvec(self, y):
        return self._op._rmatvec(y)

    def _rmatvec(self, x):
        return self._op._matvec(x)

    def _matmat(self, Y):
        return self._op._rmatmat(Y)

    def _rmatmat(self, X):
        return self._op._matmat(X)

    def _adjoint(self):
        return self._op


@dataclass
class Simulation:
    """A simulated acquisition (one ADC): what ``simulate`` returns."""

    scene: np.ndarray
    pulse: np.ndarray
    codes: np.ndarray
    meas: np.ndarray
    meta: dict = field(default_factory=dict)

    def operator(self, dtype=None, debiased=False) -> RdOperator:
        """The operator that took these measurements (in the measurements' dtype by default)."""
        dt = self.meas.dtype if dtype is None else dtype
        return RdOperator(self.pulse, self.codes, self.scene.shape[2], dtype=dt, debiased=debiased)


def _seed(seed) -> int:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise TypeError(f"seed: expected an int, got {type(seed).__name__}")
    if not 0 <= int(seed) < 2**64:
        raise ValueError(f"seed: must be an integer in [0, 2**64), got {seed}")
    return int(seed)


def _size(size) -> Tuple[int, int, int]:
    try:
        m, n, ks = (int(v) for v in size)
    except (TypeError, ValueError):
        raise TypeError(f"size: expected (M, N, K_s), got {size!r}") from None
    return m, n, ks


def simulate(
    scene: str = "paper",
    size=(32, 32, 40),
    pulse_len: int = 4000,
    seed: int = 0,
    snr_db: Optional[float] = None,
    ternary_zero_prob: Optional[float] = None,
    lit_fraction: Optional[float] = None,
    dtype=np.float64,
) -> Simulation:
    """Simulates an acquisition with one ADC, as ``rdlidar simulate`` does.

    Parameters
    ----------
    scene : "paper", "transparent" or "random"
        The paper's scene (a square, a disk and a slanted plane), a semi-transparent one (1 to 3
        returns per lit pixel), or random opaque returns in ``lit_fraction`` of the pixels.
    size : (M, N, K_s)
    pulse_len : K_p
    seed : the base seed of every random draw.
    snr_db : Gaussian noise at this SNR on the measurements (None: noise-free).
    ternary_zero_prob : codes in {-1, 0, 1} with zeros of this probability (None: +-1 codes).
    dtype : numpy.float32 or numpy.float64, of the scene, pulse and measurements.

    Returns a ``Simulation`` with ``scene`` (M, N, K_s), ``pulse`` (K_p,), ``codes`` int8
    (M, N, K), ``meas`` (K,) and ``meta``.
    """
    dt = _real_dtype(dtype)
    d = _rdlidar.simulate(
        str(scene),
        _size(size),
        int(pulse_len),
        _seed(seed),
        None if snr_db is None else float(snr_db),
        None if ternary_zero_prob is None else float(ternary_zero_prob),
        None if lit_fraction is None else float(lit_fraction),
        dt == np.float64,
    )
    return Simulation(d["scene"], d["pulse"], d["codes"], d["meas"], d["meta"])


def reconstruct(
    pulse,
    codes,
    meas,
    depth_bins: int,
    solver: str = "auto",
    max_iter: Optional[int] = None,
    callback: Optional[Callable[[dict], Any]] = None,
    dtype=None,
    seed: int = 0,
):
    """Reconstructs a scene from one ADC's measurements, as ``rdlidar reconstruct`` does.

    Parameters
    ----------
    pulse, codes, depth_bins : as for ``RdOperator``; ``pulse`` may also be an ``RdOperator``
        (then ``codes`` and ``depth_bins`` are ignored and may be None).
    meas : array_like, shape (K,)
    solver : one of ``SOLVERS`` ("auto" chooses from the data).
    max_iter : the iteration limit of the iterative solvers (None: their defaults).
    callback : called after every iteration of an iterative solver with a dict
        (iteration, residual, objective, change, seconds); a true return value stops that
        solver. An exception raised in it stops the reconstruction and is re-raised.
        Ctrl-C interrupts the reconstruction between iterations.
    dtype : the precision (default: the measurements' dtype if float32 or float64, else
        float64).
    seed : the seed of the randomized parts (FISTA's power iteration).

    Returns ``(depth, scene, report)``: ``depth`` (M, N) int32 depth bins (-1 where no return,
    -2 for pixels no code reaches), ``scene`` (M, N, K_s) with every return found, and
    ``report`` a dict (method, method_used, regime, iterations, termination,
    residual_history, forward/adjoint/support applies, seconds, and auto's stages).
    """
    if callback is not None and not callable(callback):
        raise TypeError("callback: expected a callable or None")
    if max_iter is not None and (isinstance(max_iter, bool) or not isinstance(max_iter, (int, np.integer))):
        raise TypeError(f"max_iter: expected an int or None, got {type(max_iter).__name__}")
    if max_iter is not None and max_iter < 1:
        raise ValueError(f"max_iter: must be at least 1, got {max_iter}")
    if not isinstance(solver, str):
        raise TypeError(f"solver: expected a name (one of {', '.join(SOLVERS)})")
    if isinstance(pulse, RdOperator):
        op = pulse
        if dtype is not None and np.dtype(dtype) != op.dtype:
            raise ValueError(f"dtype: the operator is {op.dtype}, not {np.dtype(dtype)}")
    else:
        if dtype is None:
            m = np.asarray(meas)
            dtype = m.dtype if m.dtype in (np.float32, np.float64) else np.float64
        op = RdOperator(pulse, codes, depth_bins, dtype=dtype)
    if op.debiased:
        raise ValueError("pulse: reconstruct needs the operator of the physical pulse, not debiased")
    y = _real_array(meas, op.dtype, "meas")
    if y.shape != (op.samples,):
        raise ValueError(f"meas: expected shape ({op.samples},), got {y.shape}")
    depth, scene, report = _rdlidar.reconstruct(
        op._core, y, solver, None if max_iter is None else int(max_iter), callback, _seed(seed)
    )
    return depth, scene.reshape(op.scene_shape), report


def fista(
    op: RdOperator,
    meas,
    lam: float,
    step: Optional[float] = None,
    niter: int = 100,
    nonnegative: bool = False,
    restart: bool = False,
    tol: Optional[float] = None,
    callback: Optional[Callable[[dict], Any]] = None,
):
    """FISTA on 0.5 ||A x - y||^2 + lam ||x||_1 from x = 0, in the operator's dtype.

    Each iteration is ``x = soft(z - step * A^T (A z - y), lam * step)`` followed by the usual
    momentum step, for ``niter`` iterations (or until the relative change of x falls below
    ``tol``). ``step`` is 1/L; by default L is a power-iteration estimate of ||A||^2 (times
    1.01). ``restart`` resets the momentum when the objective would increase; ``nonnegative``
    constrains x >= 0.

    PyLops' ``fista(Op, y, niter=n, eps=e, alpha=a)`` runs the same iteration with
    ``lam = e / 2`` and ``step = a``.

    Returns ``(x, report)``: x of shape (M*N*K_s,) and the solver's report (iterations,
    termination, residual and objective histories, applications, seconds).
    """
    if not isinstance(op, RdOperator):
        raise TypeError(f"op: expected an rdlidar.RdOperator, got {type(op).__name__}")
    if callback is not None and not callable(callback):
        raise TypeError("callback: expected a callable or None")
    if isinstance(niter, bool) or not isinstance(niter, (int, np.integer)):
        raise TypeError(f"niter: expected an int, got {type(niter).__name__}")
    if niter < 1:
        raise ValueError(f"niter: must be at least 1, got {niter}")
    if not (np.isfinite(lam) and lam >= 0):
        raise ValueError(f"lam: must be finite and >= 0, got {lam}")
    y = _real_array(meas, op.dtype, "meas")
    if y.shape != (op.samples,):
        raise ValueError(f"meas: expected shape ({op.samples},), got {y.shape}")
    return _rdlidar.fista(
        op._core,
        y,
        float(lam),
        None if step is None else float(step),
        int(niter),
        bool(nonnegative),
        bool(restart),
        None if tol is None else float(tol),
        callback,
    )


def dot_test(op: RdOperator, seed: int = 0, tolerance: Optional[float] = None) -> dict:
    """The dot test <A x, y> = <x, A^T y> of an ``RdOperator`` with Gaussian x, y from ``seed``.

    Returns a dict: lhs, rhs, gap (relative to the larger of ||Ax|| ||y|| and ||x|| ||A^T y||),
    tolerance (by default that of the dtype) and passed.
    """
    if not isinstance(op, RdOperator):
        raise TypeError(f"op: expected an rdlidar.RdOperator, got {type(op).__name__}")
    return op._core.dot_test(int(seed), tolerance)


def metrics(truth, estimate, tau_s: Optional[float] = None) -> dict:
    """Detection and error metrics of an estimated scene against the true one.

    Both (M, N, K_s). A pixel's depth is its strongest return; ``tau_s`` is the depth bin's
    duration (default 200 ps). Returns a dict: exact_fraction, missed, false_detections,
    depth_rmse_bins, relative_error, and the per-return counts for multi-return scenes.
    """
    t = _real_array(truth, np.float64, "truth")
    e = _real_array(estimate, np.float64, "estimate")
    if t.ndim != 3 or e.shape != t.shape:
        raise ValueError(
            f"estimate: expected two scenes of the same shape (M, N, K_s), got {t.shape} and {e.shape}"
        )
    return _rdlidar.metrics(t, e, tau_s)
