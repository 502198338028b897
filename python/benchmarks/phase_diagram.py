"""Phase diagram of the hard regimes: measurements per lit pixel x SNR -> depths recovered.

For each scene, each number of measurements per lit pixel and each SNR, the script simulates an
acquisition with the command line (``rdlidar simulate`` for the pulse and codes, ``rdlidar
forward`` for the measurements), adds white Gaussian noise at the SNR (sigma^2 = mean(y^2) /
10^(SNR/10), the definition of ``rdlidar simulate --snr-db``, drawn here with numpy from the run's
seed), reconstructs with ``rdlidar reconstruct --solver auto`` and compares its depth map with
the truth: the share of lit pixels at the exact depth and within one bin, and the false returns'
share of the empty pixels, with the wall-clock time of the reconstruction.

Two scenes: the paper's (a square, a disk and a slanted plane of constant reflectivities) and a
drawn one with curved surfaces and textured reflectivity ("surfaces": a sphere, a cylinder, a
staircase and a slanted wall, the top rows empty).

Several builds can be compared in one run (``--bin before=PATH --bin after=PATH``), each run of
each build on the same files. Prints one markdown table per scene and build.

    python python/benchmarks/phase_diagram.py --bin rdlidar=target/release/rdlidar
"""

import argparse
import os
import subprocess
import sys
import tempfile
import time

import numpy as np


def surfaces_scene(m: int, n: int, ks: int, seed: int) -> np.ndarray:
    """A drawn scene with piecewise-smooth depth and textured reflectivity, (m, n, ks)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:m, 0:n].astype(float)
    u, v = yy / m, xx / n
    # A slanted back wall, the top fifth empty.
    depth = 0.75 + 0.2 * v
    lit = u > 0.2
    # A staircase of three steps on the left.
    stairs = (v < 0.3) & (u > 0.55)
    depth = np.where(stairs, 0.35 + 0.1 * np.floor((u - 0.55) / 0.15), depth)
    # A cylinder (depth varies across it) in the middle.
    cyl = (np.abs(v - 0.55) < 0.12) & (u > 0.3)
    depth = np.where(cyl, 0.45 + 0.25 * ((v - 0.55) / 0.12) ** 2, depth)
    # A sphere on the right.
    r2 = (u - 0.6) ** 2 + (v - 0.85) ** 2
    sphere = r2 < 0.15**2
    depth = np.where(sphere, 0.2 + 0.3 * (1 - np.sqrt(np.clip(1 - r2 / 0.15**2, 0, 1))), depth)
    lit = lit | sphere
    # Textured reflectivity: a smooth random field, stripes on the wall, in [0.25, 1].
    field = rng.standard_normal((m // 4 + 2, n // 4 + 2))
    field = np.kron(field, np.ones((4, 4)))[:m, :n]
    k = np.ones(5) / 5
    field = np.apply_along_axis(lambda r: np.convolve(r, k, mode="same"), 1, field)
    field = np.apply_along_axis(lambda c: np.convolve(c, k, mode="same"), 0, field)
    refl = 0.6 + 0.25 * field / (np.abs(field).max() + 1e-12)
    refl = np.where(~(stairs | cyl | sphere) & (np.floor(xx / 6) % 2 == 0), refl * 0.7, refl)
    refl = np.clip(refl, 0.25, 1.0)
    bins = np.clip(np.round(depth * (ks - 1)), 0, ks - 1).astype(int)
    x = np.zeros((m, n, ks))
    ii, jj = np.nonzero(lit)
    x[ii, jj, bins[ii, jj]] = refl[ii, jj]
    return x


def run(cmd, what):
    out = subprocess.run(cmd, capture_output=True, text=True)
    if out.returncode != 0:
        sys.exit(f"{what} failed: {out.stderr.strip()}")
    return out.stdout + out.stderr


def judge(d, truth):
    """(exact %, within one bin %, false % of empty) of the depth map d.npy against the truth."""
    est = np.load(f"{d}/d.npy")
    lit = (truth != 0).any(axis=-1)
    depth = np.where(lit, np.abs(truth).argmax(axis=-1), -1)
    found = est >= 0
    exact = (found & lit & (est == depth)).sum() / max(lit.sum(), 1)
    near = (found & lit & (np.abs(est - depth) <= 1)).sum() / max(lit.sum(), 1)
    false = (found & ~lit).sum() / max((~lit).sum(), 1)
    return 100 * exact, 100 * near, 100 * false


def reconstruct(binary, d, ks, truth):
    t0 = time.perf_counter()
    run(
        [binary, "reconstruct", "--pulse", f"{d}/pulse.npy", "--codes", f"{d}/codes.npy",
         "--meas", f"{d}/y.npy", "--depth-bins", str(ks), "--solver", "auto",
         "--out-depth", f"{d}/d.npy", "--out-scene", f"{d}/x.npy", "--quiet"],
        "reconstruct",
    )
    elapsed = time.perf_counter() - t0
    return judge(d, truth) + (elapsed,)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--bin", action="append", default=[],
                    help="LABEL=PATH of an rdlidar binary (repeatable; default rdlidar=rdlidar)")
    ap.add_argument("--size", default="48x48x24")
    ap.add_argument("--ratios", default="0.9,1.5,2.4,3.5",
                    help="measurements per lit pixel")
    ap.add_argument("--snr", default="none,20,10", help="SNRs in dB (none: noise-free)")
    ap.add_argument("--scenes", default="paper,surfaces")
    ap.add_argument("--seed", type=int, default=40)
    args = ap.parse_args()
    bins = [b.split("=", 1) for b in (args.bin or ["rdlidar=rdlidar"])]
    m, n, ks = (int(v) for v in args.size.split("x"))
    ratios = [float(r) for r in args.ratios.split(",")]
    snrs = [None if s == "none" else float(s) for s in args.snr.split(",")]
    first = bins[0][1]
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for scene in args.scenes.split(","):
            # The scene and its lit pixels first, to size the pulse.
            if scene == "paper":
                probe = os.path.join(tmp, "probe")
                run([first, "simulate", "--scene", "paper", "--size", args.size,
                     "--pulse-len", "8", "--out", probe, "--quiet", "--force"], "simulate")
                truth = np.load(f"{probe}/scene.npy")
            elif scene == "surfaces":
                truth = surfaces_scene(m, n, ks, args.seed)
            else:
                sys.exit(f"--scenes: unknown scene {scene!r} (paper, surfaces)")
            lit = int((truth != 0).any(axis=-1).sum())
            for ratio in ratios:
                for snr in snrs:
                    d = os.path.join(tmp, f"{scene}-{ratio}-{snr}")
                    k = max(int(round(ratio * lit)), ks)
                    kp = k - ks + 1
                    run([first, "simulate", "--scene", "paper", "--size", args.size,
                         "--pulse-len", str(kp), "--seed", str(args.seed), "--out", d,
                         "--quiet", "--force"], "simulate")
                    np.save(f"{d}/truth.npy", truth)
                    run([first, "forward", "--pulse", f"{d}/pulse.npy", "--codes",
                         f"{d}/codes.npy", "--scene", f"{d}/truth.npy", "--out", f"{d}/y.npy",
                         "--quiet"], "forward")
                    y = np.load(f"{d}/y.npy")
                    if snr is not None:
                        sigma = np.sqrt(np.mean(y.astype(np.float64) ** 2) / 10 ** (snr / 10))
                        rng = np.random.default_rng(args.seed + 2)
                        y = y + sigma * rng.standard_normal(y.shape)
                        np.save(f"{d}/y.npy", y)
                    for label, binary in bins:
                        r = reconstruct(binary, d, ks, truth)
                        results[(scene, label, ratio, snr)] = (k, lit) + r
                        print(f"{scene} {label} {ratio}/lit {snr} dB: K {k}, exact {r[0]}%, "
                              f"within one {r[1]}%, false {r[2]}% of empty, {r[3]:.1f} s",
                              file=sys.stderr, flush=True)
    for scene in args.scenes.split(","):
        for label, _ in bins:
            print(f"\n### {scene}, {args.size}, {label}\n")
            print("exact % / within one bin % / false % of empty / seconds\n")
            head = " | ".join("noise-free" if s is None else f"{s:g} dB" for s in snrs)
            print(f"| meas. per lit pixel (K) | {head} |")
            print("|---|" + "---|" * len(snrs))
            for ratio in ratios:
                cells = []
                for snr in snrs:
                    k, lit, exact, near, false, t = results[(scene, label, ratio, snr)]
                    cells.append(f"{exact:.1f} / {near:.1f} / {false:.2f} / {t:.1f}")
                print(f"| {ratio:g} ({k}) | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
