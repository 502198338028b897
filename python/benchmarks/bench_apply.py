"""Time per application of rdlidar's operator from Python, against the Rust bench and against
a PyLops operator composed of the same model, all in one run.

    python python/benchmarks/bench_apply.py [--rdlidar PATH] [--repeats N]

1. At the paper's size (100x100x40, f32, K_p 10000 and 30000): ``RdOperator.matvec`` on a
   dense scene and ``rmatvec``, and the operator restricted to the paper scene's nonzero
   voxels (``RdOperator.restrict``: its ``matvec`` is the sparse forward of that scene, its
   ``rmatvec`` the restricted adjoint), median of N timed calls after 0.5 s of warm-up calls,
   against ``rdlidar bench --json`` (the Rust kernels timed in Rust on the same scene, same
   sizes and repeats): the four figures ``rdlidar bench`` prints.
2. At a few small sizes (f64): the same operator composed in PyLops as
   ``HStack([Diagonal(s_i) * Convolve1D(pulse, fft) * Pad(0, K_p - 1)])`` over the pixels,
   checked to agree with rdlidar's, and both timed.

Prints a markdown table per part.
"""

import argparse
import json
import os
import shutil
import statistics
import subprocess
import time

import numpy as np

import rdlidar


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


def random_packed(rng, m, n, k):
    packed = rng.integers(0, 256, size=(m, n, (k + 7) // 8), dtype=np.uint8)
    pad = 8 * packed.shape[-1] - k
    packed[..., -1] &= np.uint8((0xFF << pad) & 0xFF)
    return packed


def find_binary(given):
    if given:
        return given
    here = os.path.dirname(os.path.abspath(__file__))
    built = os.path.join(here, "..", "..", "target", "release", "rdlidar")
    return built if os.path.exists(built) else shutil.which("rdlidar")


def part_rust(binary, repeats):
    print("| size | K_p | dtype | apply | Python (ms) | Rust bench (ms) | Python / Rust |")
    print("|---|---:|---|---|---:|---:|---:|")
    for kp in (10000, 30000):
        m, n, ks = 100, 100, 40
        rng = np.random.default_rng(0)
        pulse = (rng.random(kp) < 0.5).astype(np.float64)
        k = kp + ks - 1
        op = rdlidar.RdOperator(pulse, random_packed(rng, m, n, k), ks, dtype=np.float32)
        x = rng.random(m * n * ks).astype(np.float32)
        y = rng.standard_normal(k).astype(np.float32)
        py_fwd = median_time(lambda: op.matvec(x), repeats)
        py_adj = median_time(lambda: op.rmatvec(y), repeats)
        # The paper scene's support, as the Rust bench's sparse and restricted timings use.
        scene = rdlidar.simulate("paper", (m, n, ks), 1, seed=0).scene.ravel()
        voxels = np.flatnonzero(scene)
        restricted = op.restrict(voxels)
        values = scene[voxels].astype(np.float32)
        py_sparse = median_time(lambda: restricted.matvec(values), repeats)
        py_restricted = median_time(lambda: restricted.rmatvec(y), repeats)
        out = subprocess.run(
            [binary, "bench", "--size", f"{m}x{n}x{ks}", "--pulse-len", str(kp),
             "--precision", "f32", "--repeats", str(repeats), "--json"],
            check=True, capture_output=True, text=True,
        )
        rust = json.loads(out.stdout)
        for name, py, key in (
            ("forward", py_fwd, "forward"),
            ("adjoint", py_adj, "adjoint"),
            ("sparse forward", py_sparse, "sparse_forward"),
            ("restricted adjoint", py_restricted, "restricted_adjoint"),
        ):
            r = rust[key]["median_s"]
            print(f"| {m}x{n}x{ks} | {kp} | float32 | {name} | {1e3 * py:.2f} | {1e3 * r:.2f} "
                  f"| {py / r:.3f} |")
    print(f"\nkernels: {op.isa}")


def pylops_operator(pulse, codes, ks):
    import pylops

    m, n, k = codes.shape
    kp = len(pulse)
    blocks = []
    for i in range(m):
        for j in range(n):
            pad = pylops.Pad(ks, (0, kp - 1), dtype="float64")
            conv = pylops.signalprocessing.Convolve1D(k, h=pulse, offset=0, method="fft",
                                                      dtype="float64")
            diag = pylops.Diagonal(codes[i, j].astype(np.float64), dtype="float64")
            blocks.append(diag * conv * pad)
    return pylops.HStack(blocks, dtype="float64")


def part_pylops(repeats):
    print("| size | K_p | apply | PyLops (ms) | rdlidar (ms) | PyLops / rdlidar | agreement |")
    print("|---|---:|---|---:|---:|---:|---:|")
    for m, n, ks, kp in ((4, 4, 40, 1000), (8, 8, 40, 2000), (16, 16, 40, 4000)):
        rng = np.random.default_rng(1)
        pulse = (rng.random(kp) < 0.5).astype(np.float64)
        k = kp + ks - 1
        codes = np.where(rng.random((m, n, k)) < 0.5, -1, 1).astype(np.int8)
        ours = rdlidar.RdOperator(pulse, codes, ks, dtype=np.float64)
        theirs = pylops_operator(pulse, codes, ks)
        x = rng.random(m * n * ks)
        y = rng.standard_normal(k)
        agree = max(
            np.linalg.norm(theirs @ x - ours @ x) / np.linalg.norm(ours @ x),
            np.linalg.norm(theirs.H @ y - ours.H @ y) / np.linalg.norm(ours.H @ y),
        )
        reps = max(3, repeats // 3)
        for name, a, b in (
            ("forward", lambda: theirs.matvec(x), lambda: ours.matvec(x)),
            ("adjoint", lambda: theirs.rmatvec(y), lambda: ours.rmatvec(y)),
        ):
            ta = median_time(a, reps)
            tb = median_time(b, repeats)
            print(f"| {m}x{n}x{ks} | {kp} | {name} | {1e3 * ta:.2f} | {1e3 * tb:.3f} "
                  f"| {ta / tb:.0f} | {agree:.1e} |")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rdlidar", help="the rdlidar binary (default: target/release/rdlidar)")
    ap.add_argument("--repeats", type=int, default=15)
    a = ap.parse_args()
    binary = find_binary(a.rdlidar)
    print(f"rdlidar {rdlidar.__version__}\n")
    if binary:
        part_rust(binary, a.repeats)
    else:
        print("(no rdlidar binary found: pass --rdlidar PATH for the comparison with Rust)")
    print()
    part_pylops(a.repeats)


if __name__ == "__main__":
    main()
