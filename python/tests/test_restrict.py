"""The operator restricted to a list of voxels (``RdOperator.restrict``): equal to the whole
operator on vectors that vanish elsewhere, its adjoint the listed entries of the whole adjoint,
for one ADC (its own kernels), three ADCs (theirs, stacked) and tiles (the whole operator); bad voxel lists are refused
naming the argument."""

import numpy as np
import pytest
import scipy.sparse.linalg as spla

import rdlidar
from conftest import random_problem

TOL = {np.float32: 2e-5, np.float64: 1e-12}


def rel(a, b):
    return np.linalg.norm(a - b) / max(np.linalg.norm(b), 1e-300)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("ternary", [False, True])
@pytest.mark.parametrize("layout", ["one ADC", "three ADCs", "tiles"])
def test_restriction_is_the_whole_operator_on_the_listed_voxels(dtype, ternary, layout):
    m, n, ks, kp = 4, 6, 7, 300
    pulse, codes = random_problem(m, n, ks, kp, seed=3, ternary=ternary)
    tiles = (2, 3) if layout == "tiles" else None
    if layout == "three ADCs":
        sets = [random_problem(m, n, ks, kp, seed=3 + g, ternary=ternary)[1] for g in range(3)]
        codes = np.stack(sets)
    op = rdlidar.RdOperator(pulse, codes, ks, dtype=dtype, tiles=tiles)
    rng = np.random.default_rng(5)
    # Several voxels in some pixels, a repeat, and not in increasing order.
    voxels = rng.choice(m * n * ks, size=40, replace=False)
    voxels = np.concatenate([voxels, voxels[:1]])
    r = op.restrict(voxels)
    assert isinstance(r, spla.LinearOperator)
    assert r.shape == (op.shape[0], len(voxels)) and r.dtype == np.dtype(dtype)
    b = rng.random(len(voxels)).astype(dtype)
    x = np.zeros(op.shape[1], dtype=np.float64)
    np.add.at(x, voxels, b.astype(np.float64))
    assert rel(r.matvec(b), op.matvec(x.astype(dtype))) <= TOL[dtype]
    y = rng.standard_normal(op.shape[0]).astype(dtype)
    assert rel(r.rmatvec(y), op.rmatvec(y)[voxels]) <= TOL[dtype]
    # The dot test of the restriction itself, and SciPy's solvers run on it.
    lhs = float(np.dot(r.matvec(b).astype(np.float64), y))
    rhs = float(np.dot(b.astype(np.float64), r.rmatvec(y)))
    assert abs(lhs - rhs) <= 10 * TOL[dtype] * abs(lhs)
    distinct = np.unique(voxels)
    truth = rng.random(len(distinct)).astype(dtype) + 0.5
    rd = op.restrict(distinct)
    fit = spla.lsqr(rd, rd.matvec(truth), atol=1e-12, btol=1e-12, iter_lim=500)[0]
    assert rel(fit, truth) <= 1e3 * TOL[dtype]


def test_bad_voxel_lists_are_refused_naming_the_argument():
    pulse, codes = random_problem(2, 3, 4, 50, seed=1, ternary=False)
    op = rdlidar.RdOperator(pulse, codes, 4)
    n = op.shape[1]
    for bad, kind in (
        ([0, n], ValueError),
        ([-1], ValueError),
        ([[0, 1]], ValueError),
        ([0.5], TypeError),
    ):
        with pytest.raises(kind, match="voxels"):
            op.restrict(bad)
    # An empty list is a restriction to nothing: zero measurements, an empty adjoint.
    e = op.restrict([])
    assert e.shape == (op.shape[0], 0)
    assert e.matvec(np.zeros(0, dtype=np.float32)).shape == (op.shape[0],)
    assert e.rmatvec(np.ones(op.shape[0], dtype=np.float32)).shape == (0,)
    # The operator keeps its own copy of the list: changing the caller's array changes nothing.
    given = np.array([3, 1, 4], dtype=np.int64)
    r = op.restrict(given)
    y = np.arange(op.shape[0], dtype=np.float32)
    before = r.rmatvec(y)
    given[:] = 0
    assert np.array_equal(r.rmatvec(y), before)
    assert not r.voxels.flags.writeable
