"""rdlidar: compressive time-of-flight lidar by random demodulation.

The fast measurement operator of the random-demodulation lidar and its reconstruction methods,
from numpy, SciPy and PyLops. See docs/python.md in the repository.

Arrays
------
Inputs are converted with ``numpy.ascontiguousarray`` to the dtype each function documents
(the operator's dtype for scenes and measurements, float64 for pulses, int8 or packed uint8 for
codes): Fortran-ordered, strided and other-dtype real arrays are accepted and copied; complex
arrays, and arrays whose values do not fit (codes outside -1, 0, 1), are refused with
``TypeError`` or ``ValueError``; values that overflow the dtype, or underflow it to all zeros,
are refused. Errors of the library are ``ValueError`` with its one-line message naming the
argument; a problem beyond the memory available is a ``MemoryError`` raised before anything is
allocated. Every architecture of the command line is reachable: G code sets, tiles, coded
apertures, and codes described by a seed (a path to their ``meta.json``).
"""

from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass, field
from typing import Any, Callable, Optional, Tuple

import numpy as np
from scipy.sparse.linalg import LinearOperator

from . import _rdlidar
from ._rdlidar import __version__

__all__ = [
    "RdOperator",
    "RestrictedOperator",
    "Simulation",
    "simulate",
    "reconstruct",
    "fista",
    "dot_test",
    "metrics",
    "depth_bound",
    "range_metrics",
    "points",
    "SOLVERS",
    "CODES_FORMATS",
    "__version__",
]

#: The reconstruction methods ``reconstruct`` takes, as the command line names them.
SOLVERS: Tuple[str, ...] = tuple(_rdlidar.solvers())

#: How ``simulate`` may give the codes: int8 arrays, packed uint8 arrays, or a seed.
CODES_FORMATS: Tuple[str, ...] = ("int8", "packed", "seed")

_MAX_U64 = 2**64 - 1


def _int(value, name: str, minimum: int = 0, maximum: int = _MAX_U64) -> int:
    """An integer argument: Python or NumPy integers only (not bool, float or str), in
    [minimum, maximum]."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name}: expected an int, got {type(value).__name__} {value!r:.40}")
    v = int(value)
    if v < minimum:
        raise ValueError(f"{name}: must be at least {minimum}, got {v}")
    if v > maximum:
        raise ValueError(f"{name}: must be at most {maximum}, got {v}")
    return v


def _optional_int(value, name: str, minimum: int = 0, maximum: int = _MAX_U64) -> Optional[int]:
    return None if value is None else _int(value, name, minimum, maximum)


def _float(value, name: str) -> float:
    """A real argument: Python or NumPy reals (not bool, str or complex), finite or not as the
    callee decides."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name}: expected a real number, got {type(value).__name__} {value!r:.40}")
    return float(value)


def _optional_float(value, name: str) -> Optional[float]:
    return None if value is None else _float(value, name)


def _noise(noise) -> str:
    """``noise=``: "gaussian" or "photon"."""
    if not isinstance(noise, str):
        raise TypeError(f"noise: expected \"gaussian\" or \"photon\", got {noise!r:.40}")
    return noise


def _tiles(tiles) -> Optional[Tuple[int, int]]:
    """``tiles=(A, B)``: a tile of A rows and B columns of pixels, or None."""
    if tiles is None:
        return None
    if not isinstance(tiles, (tuple, list, np.ndarray)) or len(tiles) != 2:
        raise TypeError(f"tiles: expected (A, B), got {tiles!r:.40}")
    return (_int(tiles[0], "tiles", 1), _int(tiles[1], "tiles", 1))


def _real_dtype(dtype: Any) -> np.dtype:
    try:
        dt = np.dtype(dtype)
    except TypeError:
        raise TypeError(f"dtype: rdlidar computes in float32 or float64, not {dtype!r:.40}") from None
    if dt not in (np.dtype(np.float32), np.dtype(np.float64)):
        raise TypeError(f"dtype: rdlidar computes in float32 or float64, not {dt}")
    return dt


def _real_array(a: Any, dtype: np.dtype, what: str) -> np.ndarray:
    """``a`` as a contiguous array of ``dtype``; values that overflow ``dtype`` or that
    underflow it to all zeros are refused."""
    arr = np.asarray(a)
    if arr.dtype.kind == "c":
        raise TypeError(f"{what}: complex values are not supported (the operator is real)")
    if arr.dtype.kind not in "fiub":
        raise TypeError(f"{what}: expected a real numeric array, got dtype {arr.dtype}")
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        # ascontiguousarray makes a 0-d array 1-D: keep the shape given, so that a scalar
        # where an array is expected is refused as the command line refuses it.
        out = np.ascontiguousarray(arr, dtype=dtype).reshape(arr.shape)
    if arr.dtype != out.dtype and arr.size:
        with np.errstate(all="ignore"):
            lost = np.isfinite(arr) & ~np.isfinite(out)
        if lost.any():
            i = tuple(int(j) for j in np.argwhere(lost)[0])
            raise ValueError(f"{what}: entry {i} ({arr[i]!r}) overflows {out.dtype}")
        if not out.any() and arr.any():
            raise ValueError(
                f"{what}: every value underflows {out.dtype} to zero (the largest is "
                f"{float(np.max(np.abs(arr))):.3g}); scale it up or use float64"
            )
    return out


def _codes_argument(codes: Any):
    """Codes as the core takes them: a path (a codes .npy file or a seeded meta.json), or an
    int8 / packed uint8 array of 3 or 4 dimensions (other integer and float arrays holding -1,
    0, 1 are converted to int8)."""
    if isinstance(codes, (str, os.PathLike)):
        return os.fspath(codes)
    if isinstance(codes, dict):
        raise TypeError("codes: pass the path of the meta.json, not its contents")
    c = np.asarray(codes)
    if c.ndim not in (3, 4):
        raise ValueError(
            "codes: expected a 3-D array (M, N, K), a 4-D array (G, M, N, K) of G code sets "
            f"(packed: last axis ceil(K/8)), or the path of a seeded meta.json; got shape {c.shape}"
        )
    if c.dtype == np.bool_:
        raise TypeError("codes: expected int8 codes of -1, 0, 1 or packed uint8 bytes, not bool")
    if c.dtype in (np.uint8, np.int8):
        return c
    if c.dtype.kind == "c" or c.dtype.kind not in "fiub":
        raise TypeError(f"codes: expected int8 codes or packed uint8 bytes, got dtype {c.dtype}")
    bad = ~np.isin(c, (-1, 0, 1))
    if bad.any():
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        raise ValueError(f"codes: entry {idx} is {c[idx]!r}, not one of -1, 0, 1")
    return np.ascontiguousarray(c, dtype=np.int8)


def _rows(rows) -> Optional[Tuple[int, int]]:
    if rows is None:
        return None
    try:
        start, stop = rows
    except (TypeError, ValueError):
        raise TypeError(f"rows: expected (start, stop), got {rows!r}") from None
    start = _int(start, "rows", 0)
    stop = _int(stop, "rows", 0)
    if stop <= start:
        raise ValueError(f"rows: expected start < stop, got ({start}, {stop})")
    return (start, stop)


def _band_of(codes, rows: Tuple[int, int]):
    """The pixel rows ``rows`` of an array of codes (axis 0 of (M, N, K), axis 1 of
    (G, M, N, K))."""
    axis = codes.ndim - 3
    m = codes.shape[axis]
    if rows[1] > m:
        raise ValueError(
            f"rows: rows {rows[0]}..{rows[1]} are not a band of the {m} pixel rows of the codes"
        )
    index = (slice(None),) * axis + (slice(rows[0], rows[1]),)
    return np.ascontiguousarray(codes[index])


def _check_whole_tile_rows(rows: Tuple[int, int], tile: Tuple[int, int], m: int) -> None:
    """A band of an array in tiles of A x B pixels holds whole rows of tiles."""
    a = tile[0]
    if rows[0] % a != 0 or (rows[1] % a != 0 and rows[1] != m):
        raise ValueError(
            f"rows: rows {rows[0]}..{rows[1]} cut through the tiles of {a}x{tile[1]}: a band "
            f"of an array in tiles holds whole rows of tiles (start and stop multiples of {a}, "
            f"or stop = {m})"
        )


class RdOperator(LinearOperator):
    """The random-demodulation lidar operator A of any architecture as a SciPy
    ``LinearOperator``.

    One ADC: ``y = A x`` with ``y[k] = sum_{m,n} s[m,n,k] (x[m,n,:] * p)[k]``, a scene ``x``
    of M x N pixels and K_s depth bins (flattened in C order, depth fastest) to K = K_p + K_s - 1
    samples. G code sets (codes (G, M, N, K)) give G ADCs, the stack of G such operators
    (shape (G K, M N K_s)); ``tiles=(A, B)`` gives one ADC per tile of A x B pixels (rows of
    tiles in row-major order, edge tiles clipped); a coded aperture is one ADC whose blocked
    pixels have zero codes.

    Parameters
    ----------
    pulse : array_like, shape (K_p,)
        The transmitted pulse: finite, >= 0, not all zero, representable in ``dtype``.
    codes : array_like or path
        Each pixel's codes: int8 (M, N, K) in {-1, 0, +1}, or (G, M, N, K) for G code sets;
        +-1 codes packed as ``np.packbits(S > 0, axis=-1)`` writes them (uint8, last axis
        ceil(K/8); uint8 arrays are always read as packed); other integer or float arrays with
        values in {-1, 0, 1} are converted to int8. Or the path of a codes ``.npy`` file, or of
        the ``meta.json`` that ``simulate(codes_format="seed")`` (or
        ``rdlidar simulate --codes-format seed``) writes: codes described by a seed, generated
        here (or regenerated block by block on every application when large, or with
        ``stream_codes=True``), for an architecture of that description.
    depth_bins : int
        K_s.
    dtype : numpy.float32 or numpy.float64
        The precision of the kernels (sums are accumulated in float64 either way).
    debiased : bool
        Use the zero-mean pulse p - mean(p): the adjoint is then the debiased backprojection.
    tiles : (A, B) or None
        One ADC per tile of A x B pixels (one code set).
    stream_codes : bool
        Seeded codes of one ADC: regenerate them on every application instead of holding them.
    rows : (start, stop) or None
        Only the pixel rows ``start .. stop-1``: the block A_r of the operator that maps those
        rows' unknowns, (stop - start, N, K_s), to every measurement, so that the blocks of a
        split of the rows sum to the whole (``A = [A_1 ... A_R]``, as ``pylops.HStack`` and
        ``pylops_mpi.MPIHStack`` stack them; each MPI process then holds only its own block).
        Seeded codes (a ``meta.json``) are generated for those rows only and a codes ``.npy``
        file is read for those rows only: no whole-array codes anywhere. With ``tiles``, a
        band holds whole rows of tiles (start and stop multiples of A, or stop = M) and is the
        block of its tiles: the band's unknowns to its tiles' measurements (consecutive rows of
        the (T, K) measurements), so that the blocks of the bands sit on the diagonal of the
        whole operator (``pylops.BlockDiag``, ``pylops_mpi.MPIBlockDiag``).

    ``matvec``/``rmatvec``/``matmat``/``.H`` work as for any SciPy operator, so
    ``pylops.aslinearoperator(op)`` gives a PyLops operator. ``forward`` and ``adjoint`` also
    take and return (M, N, K_s) scenes and ``meas_shape`` measurements ((K,) for one ADC,
    (R, K) for R ADCs). Inputs must be finite, and results that overflow are refused. The
    kernels run without the GIL. A problem beyond the memory available raises
    ``MemoryError`` before anything is allocated.
    """

    def __init__(
        self,
        pulse,
        codes,
        depth_bins,
        dtype=np.float32,
        debiased=False,
        tiles=None,
        stream_codes=False,
        rows=None,
    ):
        dt = _real_dtype(dtype)
        p = _real_array(pulse, np.float64, "pulse")
        if p.ndim != 1:
            raise ValueError(f"pulse: expected a 1-D array (K_p,), got shape {p.shape}")
        ks = _int(depth_bins, "depth_bins", 1)
        band = _rows(rows)
        tile = _tiles(tiles)
        c = _codes_argument(codes)
        if band is not None and isinstance(c, np.ndarray):
            if tile is not None:
                _check_whole_tile_rows(band, tile, c.shape[c.ndim - 3])
            c, band = _band_of(c, band), None
        self._core = _rdlidar._Operator(
            p,
            c,
            ks,
            dt == np.float64,
            bool(debiased),
            tile,
            bool(stream_codes),
            band,
        )
        m, n, ks = self._core.geometry
        #: (M, N, K_s)
        self.scene_shape = (m, n, ks)
        #: K = K_p + K_s - 1, the samples of one ADC
        self.samples = self._core.samples
        #: rows of the measurements: None for one ADC, R for R ADCs
        self.rows = self._core.rows
        #: the shape of the measurements: (K,) or (R, K)
        self.meas_shape = (self.samples,) if self.rows is None else (self.rows, self.samples)
        #: "single", "multi_adc" or "tiles"
        self.architecture = self._core.architecture
        #: (A, B) of a tiled acquisition, None otherwise
        self.tiles = self._core.tiles
        self.debiased = bool(debiased)
        super().__init__(dtype=dt, shape=(int(np.prod(self.meas_shape)), m * n * ks))

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
        """y = A x for a scene of shape (M, N, K_s) (or flat); returns ``meas_shape``."""
        x = _real_array(x, self.dtype, "x")
        if x.shape not in (self.scene_shape, (self.shape[1],)):
            raise ValueError(
                f"x: expected shape {self.scene_shape} or ({self.shape[1]},), got {x.shape}"
            )
        return self._core.forward(x.reshape(-1)).reshape(self.meas_shape)

    def adjoint(self, y):
        """x = A^T y for measurements of ``meas_shape`` (or flat); returns (M, N, K_s)."""
        y = _real_array(y, self.dtype, "y")
        if y.shape not in (self.meas_shape, (self.shape[0],)):
            raise ValueError(f"y: expected shape {self.meas_shape}, got {y.shape}")
        return self._core.adjoint(y.reshape(-1)).reshape(self.scene_shape)

    def restrict(self, voxels) -> "RestrictedOperator":
        """A R^T: the operator restricted to the columns ``voxels`` (flat scene indices in
        C order, e.g. ``np.flatnonzero(x)``; repeats allowed), as a SciPy ``LinearOperator`` of
        shape (measurements, len(voxels)).

        Its ``matvec`` maps one amplitude per listed voxel to the measurements, its ``rmatvec``
        the measurements to those voxels' values of ``A^T y``. With one ADC both cost
        O(len(voxels) K_p) instead of a whole application (the least squares of greedy solvers
        on a support), with G ADCs G times that; tiles apply the whole operator. The operator
        keeps its own read-only copy of ``voxels``.
        """
        v = np.asarray(voxels)
        if v.ndim != 1:
            raise ValueError(f"voxels: expected a 1-D array of indices, got shape {v.shape}")
        if v.size and not np.issubdtype(v.dtype, np.integer):
            raise TypeError(f"voxels: expected integer indices, got dtype {v.dtype}")
        n = self.shape[1]
        bad = np.flatnonzero((v < 0) | (v >= n)) if v.size else np.empty(0, dtype=np.int64)
        if bad.size:
            raise ValueError(
                f"voxels: entry {bad[0]} is {v[bad[0]]}, outside the scene's {n} voxels"
            )
        kept = np.array(v, dtype=np.int64)
        kept.setflags(write=False)
        return RestrictedOperator(self, kept)

    @property
    def pulse(self) -> np.ndarray:
        """The pulse the operator applies (zero-mean when debiased), float64."""
        return self._core.pulse

    @property
    def regime(self) -> str:
        """"compressive", "critical" or "redundant" (per tile for a tiled acquisition)."""
        return self._core.regime

    @property
    def streamed(self) -> bool:
        """Whether seeded codes are regenerated block by block on every application."""
        return self._core.streamed

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


class RestrictedOperator(LinearOperator):
    """A R^T: an ``RdOperator`` restricted to a list of voxels (``RdOperator.restrict``)."""

    def __init__(self, op: RdOperator, voxels: np.ndarray):
        self._op = op
        #: the listed voxels (flat scene indices), int64
        self.voxels = voxels
        super().__init__(dtype=op.dtype, shape=(op.shape[0], len(voxels)))

    def _matvec(self, b):
        b = _real_array(b, self.dtype, "b").reshape(-1)
        return self._op._core.restricted(self.voxels, b, False)

    def _rmatvec(self, y):
        y = _real_array(y, self.dtype, "y").reshape(-1)
        return self._op._core.restricted(self.voxels, y, True)

    def __repr__(self):
        return f"<RestrictedOperator: {len(self.voxels)} voxels of {self._op!r}>"


@dataclass
class Simulation:
    """A simulated acquisition: what ``simulate`` returns.

    ``codes`` is int8 ((M, N, K), or (G, M, N, K) for G ADCs; a coded aperture's blocked
    pixels have zero codes), packed uint8, or None for codes described by a seed; ``meas`` is
    (K,) for one ADC and (R, K) for R ADCs; ``meta`` is the description ``meta.json`` holds
    (a dict); ``files`` the folder the files were written to, if any; ``range`` the true
    depths in bins of a scene at continuous depths or rendered by a kernel other than delta
    (float64 (M, N), or (R, M, N) with several returns per pixel, NaN where there is none;
    None otherwise), as ``range.npy`` holds them, and ``amplitude`` their amplitudes in the
    same shape (0 where there is none).
    """

    scene: np.ndarray
    pulse: np.ndarray
    codes: Optional[np.ndarray]
    meas: np.ndarray
    meta: dict = field(default_factory=dict)
    files: Optional[str] = None
    range: Optional[np.ndarray] = None
    amplitude: Optional[np.ndarray] = None

    @property
    def tiles(self) -> Optional[Tuple[int, int]]:
        """(A, B) of a tiled acquisition, None otherwise."""
        tile = self.meta.get("architecture", {}).get("tile")
        return None if tile is None else (int(tile[0]), int(tile[1]))

    def operator(self, dtype=None, debiased=False, stream_codes=False) -> RdOperator:
        """The operator that took these measurements (in the measurements' dtype by default)."""
        dt = self.meas.dtype if dtype is None else dtype
        ks = self.scene.shape[2]
        if self.codes is not None:
            return RdOperator(self.pulse, self.codes, ks, dtype=dt, debiased=debiased,
                              tiles=self.tiles, stream_codes=stream_codes)
        # Seeded codes: their description, as meta.json holds it, in a file of its own (not
        # the folder's, which may have changed since).
        with tempfile.TemporaryDirectory() as d:
            path = os.path.join(d, "meta.json")
            with open(path, "w") as f:
                json.dump(self.meta, f)
            return RdOperator(self.pulse, path, ks, dtype=dt, debiased=debiased,
                              stream_codes=stream_codes)


def _size(size) -> Tuple[int, int, int]:
    if not isinstance(size, (tuple, list, np.ndarray)) or len(size) != 3:
        raise TypeError(f"size: expected (M, N, K_s), got {size!r:.40}")
    return tuple(_int(v, "size", 1) for v in size)


def simulate(
    scene: str = "paper",
    size=(32, 32, 40),
    pulse_len: int = 4000,
    seed: int = 0,
    snr_db: Optional[float] = None,
    ternary_zero_prob: Optional[float] = None,
    lit_fraction: Optional[float] = None,
    dtype=np.float64,
    adcs: int = 1,
    tiles=None,
    aperture: Optional[float] = None,
    codes_format: str = "int8",
    out=None,
    force: bool = False,
    depth_png=None,
    reflectivity_png=None,
    photons: Optional[float] = None,
    background: Optional[float] = None,
    adc_bits: Optional[int] = None,
    full_scale: Optional[float] = None,
    depth: str = "grid",
    kernel: Optional[str] = None,
) -> Simulation:
    """Simulates an acquisition of any architecture, as ``rdlidar simulate`` does.

    Parameters
    ----------
    scene : "paper", "transparent", "random" or "png"
        The paper's scene (a square, a disk and a slanted plane), a semi-transparent one (1 to 3
        returns per lit pixel), random opaque returns in ``lit_fraction`` of the pixels, or an
        opaque scene read from the PNG depth map ``depth_png``.
    size : (M, N, K_s)
    pulse_len : K_p
    seed : the base seed of every random draw (the command line's ``--seed``).
    snr_db : Gaussian noise at this SNR on the measurements (None: noise-free).
    ternary_zero_prob : codes in {-1, 0, 1} with zeros of this probability (None: +-1 codes).
    lit_fraction : a random scene's fraction of lit pixels (default 0.5).
    dtype : numpy.float32 or numpy.float64, of the scene, pulse and measurements.
    adcs : G ADCs, each with its own code set (codes (G, M, N, K), measurements (G, K)).
    tiles : (A, B): one ADC per tile of A x B pixels (measurements (T, K)).
    aperture : a coded aperture: the fraction in (0, 1] of the pixels that reach the ADC.
    codes_format : "int8", "packed" (``np.packbits`` bytes) or "seed" (no codes array: the
        description ``meta`` regenerates them).
    out : a folder to write the command line's files into (scene.npy, pulse.npy, codes.npy,
        meas.npy, meta.json), byte for byte the same as ``rdlidar simulate`` with the same
        settings; an existing non-empty folder is refused unless ``force``.
    depth_png : the "png" scene's depth map, a PNG file (8- or 16-bit; grayscale, or the first
        channel of colour) whose height and width are ``size``'s M and N: a value v > 0 is depth
        bin round(v / full scale * (K_s - 1)), 0 is no return.
    reflectivity_png : the "png" scene's reflectivity map (same size): amplitude v / full scale
        at each return (None: 1).
    photons : photon (shot) noise, drawn before the Gaussian noise: sample k of each ADC gets the
        noise of Poisson(photons * (light[k] + background)) counts, divided by ``photons``,
        light[k] the unmodulated light of the pixels the ADC sums (None: none).
    background : the photon noise's background light per sample, in units of intensity
        (default 0; only with ``photons``).
    adc_bits : quantize the measurements with an ADC of this many bits (1 to 32), after the
        noise (None: full precision).
    full_scale : the ADC's full scale F: samples beyond +-F are clipped (default: each ADC's
        largest sample; only with ``adc_bits``).
    depth : "grid" (each reflector in one depth bin) or "continuous" (the paper's reflectors,
        random and semi-transparent scenes and PNG depth maps unrounded), as ``--depth``.
    kernel : the system's response g that puts a reflector of amplitude a at depth d into its
        voxel column as a * g(k - d), as ``--kernel``: "delta" (the default on the grid),
        "triangle" (the default at continuous depths), "gaussian:S" or "measured:O:PATH" (a
        float64 .npy of samples of g, O per bin). With continuous depths or a kernel other
        than delta, the ``Simulation``'s ``range`` holds the true depths.

    Returns a ``Simulation``.
    """
    dt = _real_dtype(dtype)
    if not isinstance(scene, str):
        raise TypeError(f"scene: expected a name, got {type(scene).__name__}")
    if not isinstance(codes_format, str):
        raise TypeError(f"codes_format: expected one of {', '.join(CODES_FORMATS)}")
    if out is not None and not isinstance(out, (str, os.PathLike)):
        raise TypeError(f"out: expected a path, got {type(out).__name__}")
    if out is not None:
        # The library's rules, before any work (a killed writer's temporaries do not count).
        _rdlidar.check_simulation_dir(os.fspath(out), bool(force))
    d = _rdlidar.simulate(
        scene,
        _size(size),
        _int(pulse_len, "pulse_len", 1),
        _int(seed, "seed"),
        _optional_float(snr_db, "snr_db"),
        _optional_float(ternary_zero_prob, "ternary_zero_prob"),
        _optional_float(lit_fraction, "lit_fraction"),
        dt == np.float64,
        _int(adcs, "adcs", 1),
        _tiles(tiles),
        _optional_float(aperture, "aperture"),
        codes_format,
        None if out is None else os.fspath(out),
        bool(force),
        _optional_path(depth_png, "depth_png"),
        _optional_path(reflectivity_png, "reflectivity_png"),
        _optional_float(photons, "photons"),
        _optional_float(background, "background"),
        _optional_int(adc_bits, "adc_bits", 1, 32),
        _optional_float(full_scale, "full_scale"),
        _choice(depth, "depth", ("grid", "continuous")),
        _optional_str(kernel, "kernel"),
    )
    meta = json.loads(d["meta"])
    files = None if out is None else os.fspath(out)
    return Simulation(d["scene"], d["pulse"], d["codes"], d["meas"], meta, files, d["range"],
                      d["amplitude"])


def _choice(value, name, choices) -> str:
    if not isinstance(value, str):
        raise TypeError(f"{name}: expected one of {', '.join(map(repr, choices))}")
    if value not in choices:
        raise ValueError(f"{name}: expected one of {', '.join(map(repr, choices))}, got {value!r:.40}")
    return value


def _optional_str(value, name) -> Optional[str]:
    if value is None:
        return None
    if not isinstance(value, str):
        raise TypeError(f"{name}: expected a string, got {type(value).__name__}")
    return value


def _optional_path(value, name):
    if value is None:
        return None
    if not isinstance(value, (str, os.PathLike)):
        raise TypeError(f"{name}: expected a path, got {type(value).__name__}")
    return os.fspath(value)


def _clipped(clipped) -> Optional[str]:
    """``clipped=``: None, "top" or a level > 0, as the text the library parses."""
    if clipped is None:
        return None
    if isinstance(clipped, str):
        if clipped != "top":
            raise ValueError(f"clipped: expected 'top' or a level > 0, got {clipped!r:.40}")
        return clipped
    level = _float(clipped, "clipped")
    if not (np.isfinite(level) and level > 0):
        raise ValueError(f"clipped: the clipping level must be finite and > 0, got {level}")
    return repr(level)


def _callback(callback):
    if callback is not None and not callable(callback):
        raise TypeError("callback: expected a callable or None")
    return callback


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
    tiles=None,
    fill_unobserved: bool = False,
    stream_codes: bool = False,
    clipped=None,
    false_rate: Optional[float] = None,
    noise: str = "gaussian",
    background: Optional[float] = None,
    kernel: Optional[str] = None,
):
    """Reconstructs a scene from the measurements of any architecture, as
    ``rdlidar reconstruct`` does.

    Parameters
    ----------
    pulse, codes, depth_bins, tiles, stream_codes : as for ``RdOperator``; ``pulse`` may also
        be an ``RdOperator`` (then ``codes``, ``depth_bins``, ``tiles`` and ``stream_codes``
        are ignored and may be None).
    meas : array_like, shape (K,) for one ADC, (G, K) for G code sets, (T, K) for T tiles.
    solver : one of ``SOLVERS`` ("auto" chooses from the data).
    max_iter : the iteration limit of the iterative solvers (None: their defaults).
    callback : called after every iteration of an iterative solver with a dict
        (iteration, residual, objective, change, seconds; and tile for a tiled acquisition,
        whose tiles are solved in parallel); a true return value stops that solver. An
        exception raised in it stops the reconstruction and is re-raised. Ctrl-C interrupts
        the reconstruction between iterations.
    dtype : the precision (default: the measurements' dtype if float32 or float64, else
        float64).
    seed : the seed of the randomized parts (FISTA's norm estimate).
    fill_unobserved : fill the depth of pixels that reach no ADC (a coded aperture's blocked
        pixels, -2) from their neighbours, as ``--fill-unobserved`` does.
    clipped : samples the ADC clipped, left out of the data term as ``--clipped`` does: a
        level (samples with ``|meas| >= clipped`` are censored), ``"top"`` (each ADC's samples
        at its largest ``|meas|``) or None. The report then gives ``censored`` (the count) and
        ``censored_levels`` (per ADC row).
    false_rate : a false-detection rate in (0, 1), as ``--false-rate``: each return is kept only
        if its least-squares amplitude passes the test at which an empty pixel shows a false
        return with probability at most ``false_rate`` under white Gaussian noise (it holds the
        rate where the residual is noise, not with a few measurements per lit pixel). The
        report then gives ``detection`` (false_rate, bar, sigma, tested, dropped, skipped).
    noise : the noise model that sets the data term, as ``--noise``: ``"gaussian"`` (least
        squares) or ``"photon"`` (each sample's variance proportional to the light it receives
        plus ``background``: the solver runs, its estimate gives every sample's light, and when
        its residual's variance grows with the light the estimate is refined (per-pixel
        solvers) or solved again (generic ones) on the samples weighted by 1/sqrt(variance)). The report then gives ``photon`` (background, offset, scale,
        slope_z, light_share, gain, skipped).
    background : with ``noise="photon"``, the ambient light and dark counts per sample in the
        units of the scene's light (as ``simulate(background=)``; default 0).
    kernel : the system's response the scene was made with, as ``--kernel``: "delta" (depths
        on the grid, the default), "triangle", "gaussian:S" or "measured:O:PATH". With another
        kernel than delta every return's amplitude and continuous depth are estimated under
        it: the report's ``range`` holds the depths in bins (float64 (M, N), or (R, M, N) with
        several returns per pixel; NaN where there is none) and ``amplitude`` their
        amplitudes (0 where there is none), the scene is the returns
        rendered by the kernel and ``depth`` their nearest bins.

    Returns ``(depth, scene, report)``: ``depth`` (M, N) int32 depth bins (-1 where no return,
    -2 for pixels no code reaches), ``scene`` (M, N, K_s) with every return found, and
    ``report`` a dict (method, method_used, architecture, regime, solver, iterations,
    termination, residual_history, objective_history, forward/adjoint/support applies,
    seconds, solver_seconds, auto's stages, the request in these arguments' words, and a
    report per tile for a tiled acquisition), with the lines the command line prints:
    ``headline`` (the method and its regime, the work, the time, the pixels with a return)
    and ``details`` (auto's stages, the tests, the filled pixels).
    """
    callback = _callback(callback)
    max_iter = _optional_int(max_iter, "max_iter", 1)
    if not isinstance(solver, str):
        raise TypeError(f"solver: expected a name (one of {', '.join(SOLVERS)})")
    if isinstance(pulse, RdOperator):
        op = pulse
        if dtype is not None and _real_dtype(dtype) != op.dtype:
            raise ValueError(f"dtype: the operator is {op.dtype}, not {np.dtype(dtype)}")
    else:
        if dtype is None:
            m = np.asarray(meas)
            dtype = m.dtype if m.dtype in (np.float32, np.float64) else np.float64
        op = RdOperator(pulse, codes, depth_bins, dtype=dtype, tiles=tiles,
                        stream_codes=stream_codes)
    if op.debiased:
        raise ValueError("pulse: reconstruct needs the operator of the physical pulse, not debiased")
    y = _real_array(meas, op.dtype, "meas")
    if y.shape not in (op.meas_shape, (op.shape[0],)):
        raise ValueError(f"meas: expected shape {op.meas_shape}, got {y.shape}")
    depth, scene, report = _rdlidar.reconstruct(
        op._core, y.reshape(-1), solver, max_iter, callback, _int(seed, "seed"),
        bool(fill_unobserved), _clipped(clipped), _optional_float(false_rate, "false_rate"),
        _noise(noise), _optional_float(background, "background"),
        _optional_str(kernel, "kernel"),
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
    ``tol``). ``step`` is 1/L; by default L is a Lanczos estimate of ||A||^2 (times
    1.01). ``restart`` resets the momentum when the objective would increase; ``nonnegative``
    constrains x >= 0.

    PyLops' ``fista(Op, y, niter=n, eps=e, alpha=a)`` runs the same iteration with
    ``lam = e / 2`` and ``step = a``.

    Returns ``(x, report)``: x of shape (M*N*K_s,) and the solver's report (iterations,
    termination, residual and objective histories, applications, seconds).
    """
    if not isinstance(op, RdOperator):
        raise TypeError(f"op: expected an rdlidar.RdOperator, got {type(op).__name__}")
    callback = _callback(callback)
    niter = _int(niter, "niter", 1)
    lam = _float(lam, "lam")
    if not (np.isfinite(lam) and lam >= 0):
        raise ValueError(f"lam: must be finite and >= 0, got {lam}")
    step = _optional_float(step, "step")
    tol = _optional_float(tol, "tol")
    y = _real_array(meas, op.dtype, "meas")
    if y.shape not in (op.meas_shape, (op.shape[0],)):
        raise ValueError(f"meas: expected shape {op.meas_shape}, got {y.shape}")
    return _rdlidar.fista(
        op._core,
        y.reshape(-1),
        lam,
        step,
        niter,
        bool(nonnegative),
        bool(restart),
        tol,
        callback,
    )


def dot_test(op: RdOperator, seed: int = 0, tolerance: Optional[float] = None) -> dict:
    """The dot test <A x, y> = <x, A^T y> of an ``RdOperator`` with Gaussian x, y from ``seed``.

    Returns a dict: lhs, rhs, gap (relative to the larger of ||Ax|| ||y|| and ||x|| ||A^T y||),
    tolerance (by default that of the dtype) and passed.
    """
    if not isinstance(op, RdOperator):
        raise TypeError(f"op: expected an rdlidar.RdOperator, got {type(op).__name__}")
    return op._core.dot_test(_int(seed, "seed"), _optional_float(tolerance, "tolerance"))


def metrics(truth, estimate, tau_s: Optional[float] = None) -> dict:
    """Detection and error metrics of an estimated scene against the true one.

    Both (M, N, K_s). A pixel's depth is its strongest return; ``tau_s`` is the depth bin's
    duration in seconds (default 200e-12). Returns a dict: exact_fraction, within_one (lit pixels
    within one bin of their depth) and within_one_fraction, missed, false_detections,
    depth_rmse_bins, relative_error, and the per-return counts for multi-return scenes.
    """
    t = _real_array(truth, np.float64, "truth")
    e = _real_array(estimate, np.float64, "estimate")
    if t.ndim != 3 or e.shape != t.shape:
        raise ValueError(
            f"estimate: expected two scenes of the same shape (M, N, K_s), got {t.shape} and {e.shape}"
        )
    return _rdlidar.metrics(t, e, _optional_float(tau_s, "tau_s"))


def _range_array(a, what: str) -> np.ndarray:
    """A float64 (M, N) or (R, M, N) array of depths, amplitudes or bounds (NaN allowed)."""
    try:
        r = np.asarray(a, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"{what}: expected an array of numbers") from None
    if r.ndim not in (2, 3) or r.size == 0:
        raise ValueError(f"{what}: expected an (M, N) or (R, M, N) array, got shape {r.shape}")
    return np.ascontiguousarray(r)


def _returns(range, amplitude):
    d = _range_array(range, "range")
    a = _range_array(amplitude, "amplitude")
    if a.shape != d.shape:
        raise ValueError(f"amplitude: expected the shape of range {d.shape}, got {a.shape}")
    return d, a


def depth_bound(op: RdOperator, range, amplitude, kernel: str, sigma: float,
                joint: bool = False) -> np.ndarray:
    """The Cramér–Rao bound on continuous depths, in bins (a standard deviation per return).

    For the returns at depths ``range`` (bins, (M, N) or (R, M, N), NaN where there is none,
    as ``Simulation.range``) with amplitudes ``amplitude`` (same shape), the system response
    ``kernel`` (as ``reconstruct``'s, not "delta"), the operator ``op`` and white Gaussian
    noise of standard deviation ``sigma`` per sample (``Simulation.meta["noise"]["sigma"]``):
    the smallest RMSE any unbiased estimate of each depth can have when every other pixel is
    known or, with ``joint=True``, when every return's amplitude and depth are unknown at once
    (the support known; never below the first, and the limit of a method that fits all returns;
    for at most samples × (2·returns)² = 5e10 per tile). Returns float64 (R, M, N): NaN where
    there is no return, inf where the data cannot place it.
    """
    if not isinstance(op, RdOperator):
        raise TypeError(f"op: expected an rdlidar.RdOperator, got {type(op).__name__}")
    if not isinstance(joint, (bool, np.bool_)):
        raise TypeError(f"joint: expected a bool, got {type(joint).__name__}")
    d, a = _returns(range, amplitude)
    m, n, _ = op.scene_shape
    if d.shape[-2:] != (m, n):
        raise ValueError(f"range: expected the operator's ({m}, {n}) pixels, got shape {d.shape}")
    return _rdlidar.depth_bound(op._core, d, a, _optional_str(kernel, "kernel") or "",
                                _float(sigma, "sigma"), bool(joint))


def range_metrics(truth, estimate, bound=None, tau_s: Optional[float] = None) -> dict:
    """Continuous depths against the true ones: each true return paired with the nearest
    estimated one of its pixel.

    ``truth`` and ``estimate``: depths in bins, (M, N) or (R, M, N), NaN where there is none
    (``Simulation.range`` and the report's ``range``); ``bound``: ``depth_bound``'s array for
    the truth, to compare the RMSE with; ``tau_s`` the sampling period (default 200e-12).
    Returns a dict: pixels, lit, empty, true_returns, paired, missed, false_returns,
    missed_pixels, false_pixels, false_fraction_empty, rmse_bins, max_error_bins, bin_m,
    rmse_m, bound_bins and rmse_over_bound (None without a bound).
    """
    t = _range_array(truth, "truth")
    e = _range_array(estimate, "estimate")
    if e.shape[-2:] != t.shape[-2:]:
        raise ValueError(f"estimate: expected the truth's {t.shape[-2:]} pixels, got shape {e.shape}")
    b = None if bound is None else _range_array(bound, "bound")
    if b is not None and b.reshape((-1,) + b.shape[-2:]).shape != t.reshape((-1,) + t.shape[-2:]).shape:
        raise ValueError(f"bound: expected the truth's shape {t.shape}, got {b.shape}")
    return _rdlidar.range_metrics(t, e, b, _optional_float(tau_s, "tau_s"))


def points(range, amplitude, *, fov=None, pixel_pitch: Optional[float] = None,
           focal_length: Optional[float] = None, tau_s: Optional[float] = None,
           pixels: bool = False):
    """Returns as a point cloud, as ``reconstruct --out-points`` writes it.

    Each return of ``range`` (bins, (M, N) or (R, M, N), NaN where there is none) becomes a
    point at range d * c * tau_s / 2 metres along its pixel's ray, for a pinhole camera at the
    origin looking along +z (x right, y down) of field of view ``fov`` (degrees across the N
    columns, or (H, V)) or of ``pixel_pitch`` and ``focal_length`` (one unit for both); its
    intensity is its ``amplitude``. Returns float64 (P, 4): x, y, z, intensity, pixels in
    row-major order and each pixel's returns nearest first; with ``pixels=True`` also the
    uint32 (P, 2) row and column of each point.
    """
    d, a = _returns(range, amplitude)
    if fov is not None:
        if isinstance(fov, (tuple, list)):
            if len(fov) != 2:
                raise ValueError(f"fov: expected H or (H, V) in degrees, got {fov!r}")
            fov = (_float(fov[0], "fov"), _float(fov[1], "fov"))
        else:
            fov = (_float(fov, "fov"), None)
    cloud, where = _rdlidar.points(d, a, fov, _optional_float(pixel_pitch, "pixel_pitch"),
                                   _optional_float(focal_length, "focal_length"),
                                   _optional_float(tau_s, "tau_s"))
    return (cloud, where) if pixels else cloud
