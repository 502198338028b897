"""rdlidar's forward and adjoint products against numpy's GEMM on the same problem, in one run.

    env -u OPENBLAS_CORETYPE -u OPENBLAS_L2_SIZE \\
        python python/benchmarks/numpy_ratio.py [--rdlidar PATH] [--size 100x100x40]
        [--pulse-lens 10000,30000] [--repeats 5] [--rounds 1]

For each precision (f32, f64) and pulse length K_p, with S the (M N, K) matrix of +-1 codes,
X the (M N, K_s) scene and p the pulse:

- numpy forward: Z = S^T X (a GEMM, 2 M N K K_s flops), then y[k] = sum_j Z[k, j] p[k - j];
- numpy adjoint: W[k, j] = y[k] p[k - j], then X~ = S W (a GEMM of the same size);
- rdlidar: ``rdlidar bench --json`` at the same size and precision (the dense forward and the
  adjoint), with ``RDLIDAR_ISA`` as set in the environment;

median of --repeats timed calls after 0.5 s of warm-up calls each (as ``rdlidar bench``). With
--rounds R > 1 both sides are timed R times in turn (rdlidar, numpy, rdlidar, ...) and each ratio
is the median of the R rounds' ratios, with their range: on a shared machine whose load drifts,
the two sides of each ratio are then timed back to back. Prints the BLAS that numpy ran (from
threadpoolctl: OpenBLAS's kernel, e.g. SkylakeX or Haswell), a markdown table of the times and
the ratios numpy / rdlidar, and a second table of rdlidar's additions and table bytes per
second against what the caches deliver to the same access pattern (``rdlidar bench``'s
"limits"). Machines that force ``OPENBLAS_CORETYPE=Haswell`` slow numpy on
AVX-512: unset it (and ``OPENBLAS_L2_SIZE``) for this command only, as above.
"""

import argparse
import json
import math
import os
import shutil
import statistics
import subprocess
import time

import numpy as np


def median_time(f, repeats, warm_up_s=0.5):
    """The median of `repeats` timed calls of f, after calling it for at least warm_up_s seconds
    (and at least once), as ``rdlidar bench`` does: a fresh process's first calls can run far
    slower than its later ones."""
    t0 = time.perf_counter()
    f()
    while time.perf_counter() - t0 < warm_up_s:
        f()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        f()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def blas_kernel():
    try:
        from threadpoolctl import threadpool_info
    except ImportError:
        return "unknown (pip install threadpoolctl to see it)"
    blas = [i for i in threadpool_info() if i.get("user_api") == "blas"]
    if not blas:
        return "none found"
    i = blas[0]
    return (
        f"{i.get('internal_api')} {i.get('version')}, kernel {i.get('architecture')}, "
        f"{i.get('num_threads')} threads"
    )


def numpy_problem(m, n, ks, kp, dtype, rng):
    """The numpy forward and adjoint of a random problem, as functions of no arguments."""
    k = kp + ks - 1
    s = np.where(rng.random((m * n, k)) < 0.5, -1.0, 1.0).astype(dtype)
    x = rng.random((m * n, ks)).astype(dtype)
    p = (rng.random(kp) < 0.5).astype(dtype)
    y = np.empty(k, dtype=dtype)

    def forward():
        z = s.T @ x
        y[:] = 0
        for j in range(ks):
            y[j : j + kp] += z[j : j + kp, j] * p

    def adjoint():
        w = np.zeros((k, ks), dtype=dtype)
        for j in range(ks):
            w[j : j + kp, j] = y[j : j + kp] * p
        return s @ w

    forward()
    return forward, adjoint


def rdlidar_times(binary, size, kp, precision, repeats):
    out = subprocess.run(
        [
            binary,
            "--precision",
            precision,
            "bench",
            "--size",
            size,
            "--pulse-len",
            str(kp),
            "--repeats",
            str(repeats),
            "--json",
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(out.stdout)


def ratio_text(r):
    """A ratio in three significant digits, without an exponent (0.00412, 5.96, 123)."""
    if not (math.isfinite(r) and r > 0):
        return f"{r:.2f}"
    return f"{r:.{max(0, 2 - math.floor(math.log10(r)))}f}"


def ratio_cells(ours, theirs):
    """The table cells of one operation: the medians of rdlidar's and numpy's times over the
    rounds, and the median of the rounds' ratios (with their range when there are several)."""
    ratios = [t / o for o, t in zip(ours, theirs)]
    # Three significant digits: a ratio far below 1 (a debug build, a loaded machine) is still
    # printed as what it is, never as 0.00.
    cell = f"{ratio_text(statistics.median(ratios))}x"
    if len(ratios) > 1:
        cell += f" ({ratio_text(min(ratios))}–{ratio_text(max(ratios))})"
    return (
        f"{statistics.median(ours) * 1e3:.1f} ms | {statistics.median(theirs) * 1e3:.1f} ms "
        f"| {cell}"
    )


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rdlidar", default=os.environ.get("RDLIDAR_BIN") or shutil.which("rdlidar"))
    ap.add_argument("--size", default="100x100x40")
    ap.add_argument("--pulse-lens", default="10000,30000")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=1)
    a = ap.parse_args()
    if a.repeats < 1 or a.rounds < 1:
        raise SystemExit("--repeats and --rounds must be at least 1")
    if not a.rdlidar:
        raise SystemExit("give --rdlidar PATH (or RDLIDAR_BIN): the rdlidar binary to time")
    m, n, ks = (int(v) for v in a.size.lower().split("x"))
    kps = [int(v) for v in a.pulse_lens.split(",")]
    rng = np.random.default_rng(0)
    print(f"numpy {np.__version__}: {blas_kernel()}")
    print(f"OPENBLAS_CORETYPE={os.environ.get('OPENBLAS_CORETYPE', '(unset)')}")
    rows = []
    for precision, dtype in (("f32", np.float32), ("f64", np.float64)):
        for kp in kps:
            forward, adjoint = numpy_problem(m, n, ks, kp, dtype, rng)
            rounds = []
            for _ in range(a.rounds):
                # rdlidar first: OpenBLAS's threads keep spinning for a while after numpy's
                # last GEMM and would slow the subprocess's first timings.
                v = rdlidar_times(a.rdlidar, a.size, kp, precision, a.repeats)
                nf, na = median_time(forward, a.repeats), median_time(adjoint, a.repeats)
                rounds.append((v, nf, na))
            rows.append((precision, kp, rounds))
    print()
    spread = " (range)" if a.rounds > 1 else ""
    print(
        f"| {a.size} | K_p | rdlidar ISA, threads | forward rdlidar | numpy | ratio{spread} "
        f"| adjoint rdlidar | numpy | ratio{spread} |"
    )
    print("|---|---:|---|---:|---:|---:|---:|---:|---:|")
    for precision, kp, rounds in rows:
        v = rounds[0][0]
        cells = []
        for op, i in (("forward", 1), ("adjoint", 2)):
            ours = [r[0][op]["median_s"] for r in rounds]
            theirs = [r[i] for r in rounds]
            cells.append(ratio_cells(ours, theirs))
        print(f"| {precision} | {kp} | {v['isa']}, {v['threads']} | {cells[0]} | {cells[1]} |")
    # The same run's rates (its first round's) against what the caches deliver to the kernels'
    # access pattern (random table rows summed, from L1 and from L2; `rdlidar bench` measures
    # both).
    print()
    print(
        "| rdlidar | K_p | forward Gadd/s | GB/s | adjoint Gadd/s | GB/s "
        "| L1 limit GB/s | L2 limit GB/s | forward / L2 | adjoint / L2 |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for precision, kp, rounds in rows:
        v = rounds[0][0]
        f, d = v["rates"]["forward"], v["rates"]["adjoint"]
        l1, l2 = v["limits"]["l1"]["bytes_per_s"], v["limits"]["l2"]["bytes_per_s"]
        print(
            f"| {precision} | {kp} | {f['additions_per_s'] / 1e9:.1f} "
            f"| {f['table_bytes_per_s'] / 1e9:.1f} | {d['additions_per_s'] / 1e9:.1f} "
            f"| {d['table_bytes_per_s'] / 1e9:.1f} | {l1 / 1e9:.1f} | {l2 / 1e9:.1f} "
            f"| {f['table_bytes_per_s'] / l2:.2f} | {d['table_bytes_per_s'] / l2:.2f} |"
        )


if __name__ == "__main__":
    main()
