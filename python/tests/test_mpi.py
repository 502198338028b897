"""Blocks of pixel rows (``RdOperator(..., rows=(start, stop))``) for operators split over
processes: the blocks of a split stack to the whole operator (``pylops.HStack``), for seeded
codes, codes files and arrays, one ADC and several; and inside ``pylops_mpi.MPIHStack`` under
``mpiexec -n 2``, ``pylops_mpi.cgls`` on blocks of seeded codes (no process holds the whole
array's codes) gives the serial result.

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
    with pytest.raises(ValueError, match="tiles"):
        rdlidar.RdOperator(sim.pulse, meta, 5, rows=(0, 2), tiles=(2, 2))


_SCRIPT = textwrap.dedent(
    """
    import sys
    import numpy as np
    import pylops
    import pylops_mpi
    from mpi4py import MPI

    import rdlidar

    folder, niter = sys.argv[1], int(sys.argv[2])
    comm = MPI.COMM_WORLD
    rank, size = comm.Get_rank(), comm.Get_size()
    meta = folder + "/meta.json"
    pulse = np.load(folder + "/pulse.npy")
    meas = np.load(folder + "/meas.npy")
    m, ks = 13, 8
    base, extra = divmod(m, size)
    start = rank * base + min(rank, extra)
    stop = start + base + (1 if rank < extra else 0)
    # This process's block: the codes of its rows only, generated from the seed.
    block = rdlidar.RdOperator(pulse, meta, ks, dtype=np.float64, rows=(start, stop))
    op = pylops_mpi.MPIHStack([pylops.aslinearoperator(block)])
    y = pylops_mpi.DistributedArray(
        global_shape=meas.size, partition=pylops_mpi.Partition.BROADCAST
    )
    y[:] = meas
    x0 = pylops_mpi.DistributedArray(
        global_shape=op.shape[1],
        local_shapes=comm.allgather((block.shape[1],)),
        partition=pylops_mpi.Partition.SCATTER,
    )
    x0[:] = 0.0
    x = pylops_mpi.cgls(op, y, x0, niter=niter, tol=0.0)[0].asarray()
    if rank == 0:
        whole = rdlidar.RdOperator(pulse, meta, ks, dtype=np.float64)
        serial = pylops.optimization.basic.cgls(
            pylops.aslinearoperator(whole), meas, np.zeros(whole.shape[1]), niter=niter, tol=0.0
        )[0]
        gap = np.max(np.abs(x - serial)) / np.max(np.abs(serial))
        print(f"ranks {size}: max relative gap {gap:.3e}")
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


def test_pylops_mpi_cgls_on_blocks_of_seeded_codes_is_the_serial_cgls(tmp_path):
    missing = _mpi_available()
    if missing:
        if os.environ.get("RDLIDAR_REQUIRE_MPI") == "1":
            pytest.fail(f"RDLIDAR_REQUIRE_MPI=1 but {', '.join(missing)} missing")
        pytest.skip(f"needs {', '.join(missing)}")
    rdlidar.simulate(
        size=(13, 9, 8), pulse_len=400, seed=5, codes_format="seed", out=tmp_path / "run"
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
        ["mpiexec", "-n", "2", sys.executable, str(script), str(tmp_path / "run"), "25"],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert out.returncode == 0, out.stdout + out.stderr
    assert "ranks 2: max relative gap" in out.stdout
