"""Blocks of pixel rows (``RdOperator(..., rows=(start, stop))``) for operators split over
processes: the blocks of a split stack to the whole operator (``pylops.HStack``), for seeded
codes, codes files and arrays, one ADC and several; blocks of whole rows of tiles sit on the
diagonal of a tiled array's operator (``pylops.BlockDiag``); and inside
``pylops_mpi.MPIHStack`` and ``pylops_mpi.MPIBlockDiag`` under ``mpiexec -n 2``,
``pylops_mpi.cgls`` on blocks of seeded codes (no process holds the whole array's codes) gives
the serial result.

The MPI test needs mpiexec, mpi4py and pylops-mpi; it is skipped without them unless
RDLIDAR_REQUIRE_MPI=1 (as the CI sets it), when their absence fails it.
"""

import os
import shutil
import subprocess
import sys
import textwrap

import numpy as np
import pylops
import pytest

import rdlidar


def _bands(m, parts):
    """Pixel rows split into ``parts`` bands as even as they can be, the first ones larger."""
    base, extra = divmod(m, parts)
    out, start = [], 0
    for p in range(parts):
        stop = start + base + (1 if p < extra else 0)
        out.append((start, stop))
        start = stop
    return out


@pytest.mark.parametrize("codes_format", ["seed", "int8", "packed", "array"])
@pytest.mark.parametrize("adcs", [1, 2])
def test_blocks_of_rows_stack_to_the_whole_operator(tmp_path, codes_format, adcs):
    fmt = "int8" if codes_format == "array" else codes_format
    sim = rdlidar.simulate(
        size=(7, 5, 6), pulse_len=60, seed=3, adcs=adcs, codes_format=fmt, out=tmp_path / "run"
    )
    if codes_format == "array":
        codes = sim.codes
    elif fmt == "seed":
        codes = tmp_path / "run" / "meta.json"
    else:
        codes = tmp_path / "run" / "codes.npy"
    whole = rdlidar.RdOperator(sim.pulse, codes, 6, dtype=np.float64)
    blocks = [
        rdlidar.RdOperator(sim.pulse, codes, 6, dtype=np.float64, rows=band)
        for band in _bands(7, 3)
    ]
    assert [b.scene_shape for b in blocks] == [(3, 5, 6), (2, 5, 6), (2, 5, 6)]
    stacked = pylops.HStack([pylops.aslinearoperator(b) for b in blocks])
    rng = np.random.default_rng(1)
    x = rng.standard_normal(whole.shape[1])
    y = rng.standard_normal(whole.shape[0])
    np.testing.assert_allclose(stacked @ x, whole @ x, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(stacked.H @ y, whole.H @ y, rtol=1e-12, atol=1e-12)
    # A block's forward product is its rows' share of the measurements.
    share = blocks[1].forward(sim.scene[3:5])
    assert share.shape == whole.meas_shape


@pytest.mark.parametrize("codes_format", ["seed", "int8", "array"])
def test_blocks_of_tile_rows_sit_on_the_diagonal(tmp_path, codes_format):
    fmt = "int8" if codes_format == "array" else codes_format
    sim = rdlidar.simulate(
        size=(7, 5, 6), pulse_len=60, seed=4, tiles=(2, 3), codes_format=fmt, out=tmp_path / "run"
    )
    codes = {
        "array": sim.codes,
        "seed": tmp_path / "run" / "meta.json",
        "int8": tmp_path / "run" / "codes.npy",
    }[codes_format]
    whole = rdlidar.RdOperator(sim.pulse, codes, 6, dtype=np.float64, tiles=(2, 3))
    assert whole.meas_shape == (8, 65)
    blocks = [
        rdlidar.RdOperator(sim.pulse, codes, 6, dtype=np.float64, tiles=(2, 3), rows=band)
        for band in [(0, 2), (2, 6), (6, 7)]
    ]
    # Two tiles per row of tiles: the bands hold tiles 0-1, 2-5 and 6-7.
    assert [b.meas_shape for b in blocks] == [(2, 65), (4, 65), (2, 65)]
    assert [b.scene_shape for b in blocks] == [(2, 5, 6), (4, 5, 6), (1, 5, 6)]
    diagonal = pylops.BlockDiag([pylops.aslinearoperator(b) for b in blocks])
    rng = np.random.default_rng(2)
    x = rng.standard_normal(whole.shape[1])
    y = rng.standard_normal(whole.shape[0])
    np.testing.assert_allclose(diagonal @ x, whole @ x, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(diagonal.H @ y, whole.H @ y, rtol=1e-12, atol=1e-12)
    # A band's measurements are its tiles' rows of the whole array's.
    np.testing.assert_allclose(
        blocks[1].forward(sim.scene[2:6]), sim.meas[2:6], rtol=1e-10, atol=1e-10
    )


def test_rows_are_checked(tmp_path):
    sim = rdlidar.simulate(size=(4, 4, 5), pulse_len=30, codes_format="seed", out=tmp_path / "s")
    meta = tmp_path / "s" / "meta.json"
    for rows, error, text in [
        ((2, 2), ValueError, "start < stop"),
        ((3, 9), ValueError, "rows 3..9"),
        ((1,), TypeError, "(start, stop)"),
        ((-1, 2), ValueError, "rows"),
    ]:
        for codes in (meta, sim.pulse):
            if codes is sim.pulse:
                codes = np.ones((4, 4, 34), dtype=np.int8)
            with pytest.raises(error, match=text.replace("(", r"\(").replace(")", r"\)")):
                rdlidar.RdOperator(sim.pulse, codes, 5, rows=rows)
    tiled = rdlidar.simulate(
        size=(5, 4, 5), pulse_len=30, tiles=(2, 2), codes_format="seed", out=tmp_path / "t"
    )
    for codes in (tmp_path / "t" / "meta.json", np.ones((5, 4, 34), dtype=np.int8)):
        for rows in [(1, 3), (0, 3), (1, 5)]:
            with pytest.raises(ValueError, match="cut through the tiles of 2x2"):
                rdlidar.RdOperator(tiled.pulse, codes, 5, rows=rows, tiles=(2, 2))


_SCRIPT = textwrap.dedent(
    """
    import sys
    import numpy as np
    import pylops
    import pylops_mpi
    from mpi4py import MPI

    import rdlidar

    folder, niter, stack = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    comm = MPI.COMM_WORLD
    rank, size = comm.Get_rank(), comm.Get_size()
    meta = folder + "/meta.json"
    pulse = np.load(folder + "/pulse.npy")
    meas = np.load(folder + "/meas.npy").reshape(-1)
    m, ks = 13, 8
    # hstack: pixel rows split, one ADC; blockdiag: whole rows of 3x3 tiles, one ADC per tile.
    a, tiles = (1, None) if stack == "hstack" else (3, (3, 3))
    base, extra = divmod(-(-m // a), size)
    first = rank * base + min(rank, extra)
    start, stop = first * a, min((first + base + (1 if rank < extra else 0)) * a, m)
    # This process's block: the codes of its rows only, generated from the seed.
    block = rdlidar.RdOperator(
        pulse, meta, ks, dtype=np.float64, tiles=tiles, rows=(start, stop)
    )
    scatter = pylops_mpi.Partition.SCATTER
    if stack == "hstack":
        op = pylops_mpi.MPIHStack([pylops.aslinearoperator(block)])
        y = pylops_mpi.DistributedArray(
            global_shape=meas.size, partition=pylops_mpi.Partition.BROADCAST
        )
        y[:] = meas
    else:
        op = pylops_mpi.MPIBlockDiag([pylops.aslinearoperator(block)])
        rows = comm.allgather(block.shape[0])
        y = pylops_mpi.DistributedArray(
            global_shape=meas.size, local_shapes=[(r,) for r in rows], partition=scatter
        )
        at = sum(rows[:rank])
        y[:] = meas[at : at + block.shape[0]]
    x0 = pylops_mpi.DistributedArray(
        global_shape=op.shape[1],
        local_shapes=comm.allgather((block.shape[1],)),
        partition=scatter,
    )
    x0[:] = 0.0
    x = pylops_mpi.cgls(op, y, x0, niter=niter, tol=0.0)[0].asarray()
    if rank == 0:
        whole = rdlidar.RdOperator(pulse, meta, ks, dtype=np.float64, tiles=tiles)
        serial = pylops.optimization.basic.cgls(
            pylops.aslinearoperator(whole), meas, np.zeros(whole.shape[1]), niter=niter, tol=0.0
        )[0]
        gap = np.max(np.abs(x - serial)) / np.max(np.abs(serial))
        print(f"{stack} on {size} ranks: max relative gap {gap:.3e}")
        sys.exit(0 if gap < 1e-8 else 1)
    """
)


def _mpi_available():
    missing = [name for name in ("mpi4py", "pylops_mpi") if not _importable(name)]
    if shutil.which("mpiexec") is None:
        missing.append("mpiexec")
    return missing


def _importable(name):
    try:
        __import__(name)
        return True
    except ImportError:
        return False


@pytest.mark.parametrize("stack", ["hstack", "blockdiag"])
def test_pylops_mpi_cgls_on_blocks_of_seeded_codes_is_the_serial_cgls(tmp_path, stack):
    """MPIHStack of row blocks (one ADC), MPIBlockDiag of blocks of whole tile rows (one ADC
    per tile): pylops_mpi.cgls gives pylops' serial CGLS on the whole operator."""
    missing = _mpi_available()
    if missing:
        if os.environ.get("RDLIDAR_REQUIRE_MPI") == "1":
            pytest.fail(f"RDLIDAR_REQUIRE_MPI=1 but {', '.join(missing)} missing")
        pytest.skip(f"needs {', '.join(missing)}")
    tiles = None if stack == "hstack" else (3, 3)
    rdlidar.simulate(
        size=(13, 9, 8),
        pulse_len=400,
        seed=5,
        tiles=tiles,
        codes_format="seed",
        out=tmp_path / "run",
    )
    script = tmp_path / "cgls_mpi.py"
    script.write_text(_SCRIPT)
    env = dict(os.environ)
    env.update(
        OMPI_ALLOW_RUN_AS_ROOT="1",
        OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
        OMPI_MCA_rmaps_base_oversubscribe="1",
        RAYON_NUM_THREADS="1",
    )
    out = subprocess.run(
        ["mpiexec", "-n", "2", sys.executable, str(script), str(tmp_path / "run"), "25", stack],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert out.returncode == 0, out.stdout + out.stderr
    assert f"{stack} on 2 ranks: max relative gap" in out.stdout
