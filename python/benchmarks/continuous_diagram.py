"""Continuous depth against its limit: measurements per lit pixel x SNR -> RMSE / Cramér–Rao bound.

For each system response (``--kernels``, e.g. ``triangle`` and ``gaussian:0.8``), each number of
measurements per lit pixel (``--ratios``) and each SNR (``--snr``; ``none`` for noise-free), the
script simulates the paper's scene at continuous depths (``rdlidar.simulate(depth="continuous",
kernel=...)``), reconstructs it with ``rdlidar.reconstruct(solver="auto", kernel=...)`` and with
``auto`` on the grid (no kernel: the same measurements, each depth at its nearest bin), and
compares the estimated depths with the true ones (``rdlidar.range_metrics``) against the
per-pixel bound at the simulation's noise (``rdlidar.depth_bound``, every other pixel known).

Each cell of the printed tables: RMSE / bound under noise (RMSE in bins noise-free, "exact" below
1e-6), then lit pixels missed / empty pixels with a false return, then the time with the kernel
over the grid's time (both wall-clock, in this process, on the same measurements).

    python python/benchmarks/continuous_diagram.py --size 32x32x24 --seed 1
"""

import argparse
import time

import numpy as np

import rdlidar


def cell(kernel, size, ratio, snr, seed):
    """One simulation and its two reconstructions; the cell's figures."""
    m, n, ks = size
    probe = rdlidar.simulate("paper", size=size, pulse_len=ks, seed=seed, depth="continuous",
                             kernel=kernel)
    lit = int(np.count_nonzero(~np.isnan(probe.range)))
    pulse_len = max(1, int(round(ratio * lit)) - ks + 1)
    sim = rdlidar.simulate("paper", size=size, pulse_len=pulse_len, seed=seed, snr_db=snr,
                           depth="continuous", kernel=kernel)
    t0 = time.perf_counter()
    rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, ks)
    grid = time.perf_counter() - t0
    t0 = time.perf_counter()
    _, _, report = rdlidar.reconstruct(sim.pulse, sim.codes, sim.meas, ks, kernel=kernel)
    took = time.perf_counter() - t0
    sigma = sim.meta["noise"]["sigma"] if snr is not None else 0.0
    bound = None
    if sigma > 0:
        bound = rdlidar.depth_bound(sim.operator(), sim.range, sim.amplitude, kernel, sigma)
    met = rdlidar.range_metrics(sim.range, report["range"], bound)
    return met, took, grid, pulse_len


def show(met, took, grid):
    if met["rmse_over_bound"] is not None:
        err = f"{met['rmse_over_bound']:.2f}"
    elif met["rmse_bins"] is None or met["rmse_bins"] != met["rmse_bins"]:
        err = "-"
    elif met["rmse_bins"] < 1e-6:
        err = "exact"
    else:
        err = f"{met['rmse_bins']:.3f} bins"
    return f"{err}, {met['missed_pixels']}/{met['false_pixels']}, {took:.1f}/{grid:.1f} s"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--kernels", default="triangle,gaussian:0.8")
    ap.add_argument("--size", default="32x32x24")
    ap.add_argument("--ratios", default="2.5,3,4,6,10", help="measurements per lit pixel")
    ap.add_argument("--snr", default="none,30,20,10", help="dB, or none")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    size = tuple(int(v) for v in args.size.split("x"))
    ratios = [float(r) for r in args.ratios.split(",")]
    snrs = [None if s == "none" else float(s) for s in args.snr.split(",")]
    for kernel in args.kernels.split(","):
        print(f"\n{kernel}, the paper's scene at {args.size}, seed {args.seed}: RMSE/bound "
              "(noise-free: RMSE), missed/false pixels, time with the kernel/on the grid\n")
        print("| per lit pixel (K_p) | " + " | ".join(
            "noise-free" if s is None else f"{s:g} dB" for s in snrs) + " |")
        print("|---" * (len(snrs) + 1) + "|")
        for ratio in ratios:
            cells, kp = [], None
            for snr in snrs:
                met, took, grid, kp = cell(kernel, size, ratio, snr, args.seed)
                cells.append(show(met, took, grid))
            print(f"| {ratio:g} ({kp}) | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
