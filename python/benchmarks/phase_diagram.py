"""Phase diagram of the hard regimes: measurements per lit pixel x SNR -> depths recovered.

For each scene, each number of measurements per lit pixel and each SNR, the script simulates an
acquisition with the command line (``rdlidar simulate``, with its noise flags),
reconstructs with ``rdlidar reconstruct --solver auto`` and compares its depth map with the
truth: the share of lit pixels at the exact depth and within one bin, and the false returns'
share of the empty pixels, with the wall-clock time of the reconstruction.

Scenes: the paper's ("paper": a square, a disk and a slanted plane of constant reflectivities),
and scenes read from PNG depth and reflectivity maps by ``rdlidar simulate --scene png``:
"surfaces", drawn here with curved surfaces and textured reflectivity (a sphere, a cylinder, a
staircase and a slanted wall, the top rows empty) and written as 16-bit PNGs, or your own depth
map (``--depth-png FILE`` and optionally ``--reflectivity-png FILE``, scene "png"; --size then
takes its height and width from the file, and only K_s from the option).

Several builds can be compared in one run (``--bin before=PATH --bin after=PATH``), each build on
the same files, simulated by the first. Prints one markdown table per scene and build. With
``--photon-model`` the photon-noise columns are reconstructed with ``--noise photon``.

    python python/benchmarks/phase_diagram.py --bin rdlidar=target/release/rdlidar
"""

import argparse
import os
import subprocess
import sys
import tempfile
import struct
import time
import zlib

import numpy as np


def write_png16(path: str, image: np.ndarray) -> None:
    """Writes a 2-D array of integers in [0, 65535] as a 16-bit grayscale PNG."""
    h, w = image.shape
    rows = image.astype(">u2")
    raw = b"".join(b"\x00" + rows[i].tobytes() for i in range(h))

    def chunk(kind: bytes, data: bytes) -> bytes:
        crc = zlib.crc32(kind + data) & 0xFFFFFFFF
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", crc)

    header = struct.pack(">IIBBBBB", w, h, 16, 0, 0, 0, 0)
    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header)
                + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


def png_size(path: str):
    """(height, width) of a PNG file, from its header."""
    with open(path, "rb") as f:
        head = f.read(24)
    if head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        sys.exit(f"--depth-png: {path} is not a PNG file")
    w, h = struct.unpack(">II", head[16:24])
    return h, w


def surfaces_maps(m: int, n: int, ks: int, seed: int):
    """A drawn scene with piecewise-smooth depth and textured reflectivity, as 16-bit maps:
    depth (0: no return; v > 0: bin round(v / 65535 * (ks - 1))) and reflectivity."""
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
    bins = np.clip(np.round(depth * (ks - 1)), 0, ks - 1)
    # Bin b is written as the value nearest b / (ks - 1) of full scale, at least 1 (0 is empty).
    depth16 = np.where(lit, np.maximum(np.round(bins / (ks - 1) * 65535), 1), 0)
    return depth16.astype(int), np.round(refl * 65535).astype(int)


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


def reconstruct(binary, d, ks, truth, extra=()):
    t0 = time.perf_counter()
    run(
        [binary, "reconstruct", "--pulse", f"{d}/pulse.npy", "--codes", f"{d}/codes.npy",
         "--meas", f"{d}/meas.npy", "--depth-bins", str(ks), "--solver", "auto",
         "--out-depth", f"{d}/d.npy", "--out-scene", f"{d}/x.npy", "--quiet", *extra],
        "reconstruct",
    )
    elapsed = time.perf_counter() - t0
    return judge(d, truth) + (elapsed,)


def noise_flags(noise):
    """The simulate flags of a noise column."""
    if noise is None:
        return []
    if noise.startswith("photons="):
        return ["--photons", noise.split("=", 1)[1]]
    if noise.startswith("adc="):
        return ["--adc-bits", noise.split("=", 1)[1]]
    return ["--snr-db", noise]


def column(noise, photon_model=False):
    """A noise column's heading."""
    if noise is None:
        return "noise-free"
    if noise.startswith("photons="):
        model = " (--noise photon)" if photon_model else ""
        return f"photon noise, {noise.split('=', 1)[1]} per unit{model}"
    if noise.startswith("adc="):
        return f"{noise.split('=', 1)[1]}-bit ADC"
    return f"{float(noise):g} dB"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--bin", action="append", default=[],
                    help="LABEL=PATH of an rdlidar binary (repeatable; default rdlidar=rdlidar)")
    ap.add_argument("--size", default="48x48x24")
    ap.add_argument("--ratios", default="0.9,1.5,2.4,3.5",
                    help="measurements per lit pixel")
    ap.add_argument("--snr", default="none,20,10",
                    help="noise columns: none, an SNR in dB (Gaussian noise), photons=P "
                         "(photon noise, simulate --photons P) or adc=B (a B-bit ADC, "
                         "simulate --adc-bits B, full scale at the largest sample)")
    ap.add_argument("--scenes", default="paper,surfaces",
                    help="paper, surfaces, png (the map of --depth-png)")
    ap.add_argument("--depth-png", help="a depth map for the scene png")
    ap.add_argument("--reflectivity-png", help="its reflectivity map (default: 1)")
    ap.add_argument("--seed", type=int, default=40)
    ap.add_argument("--photon-model", action="store_true",
                    help="reconstruct the photon-noise columns with --noise photon (the data "
                         "term weighted by each sample's light)")
    args = ap.parse_args()
    bins = [b.split("=", 1) for b in (args.bin or ["rdlidar=rdlidar"])]
    m, n, ks = (int(v) for v in args.size.split("x"))
    sizes = {"paper": args.size, "surfaces": args.size}
    if args.depth_png:
        h, w = png_size(args.depth_png)
        sizes["png"] = f"{h}x{w}x{ks}"
    ratios = [float(r) for r in args.ratios.split(",")]
    snrs = [None if s == "none" else s for s in args.snr.split(",")]
    for s in snrs:
        if s is not None and not s.startswith(("photons=", "adc=")):
            float(s)
    first = bins[0][1]
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for scene in args.scenes.split(","):
            if scene not in sizes:
                sys.exit(f"--scenes: unknown scene {scene!r} (paper, surfaces, png with "
                         "--depth-png)")
            # The scene's flags, and its lit pixels (from a short probe) to size the pulse.
            if scene == "paper":
                flags = ["--scene", "paper"]
            elif scene == "surfaces":
                depth16, refl16 = surfaces_maps(m, n, ks, args.seed)
                write_png16(os.path.join(tmp, "depth.png"), depth16)
                write_png16(os.path.join(tmp, "reflectivity.png"), refl16)
                flags = ["--scene", "png", "--depth-png", os.path.join(tmp, "depth.png"),
                         "--reflectivity-png", os.path.join(tmp, "reflectivity.png")]
            else:
                flags = ["--scene", "png", "--depth-png", args.depth_png]
                if args.reflectivity_png:
                    flags += ["--reflectivity-png", args.reflectivity_png]
            probe = os.path.join(tmp, "probe")
            run([first, "simulate", *flags, "--size", sizes[scene], "--pulse-len", "8",
                 "--out", probe, "--quiet", "--force"], "simulate")
            lit = int((np.load(f"{probe}/scene.npy") != 0).any(axis=-1).sum())
            for ratio in ratios:
                for snr in snrs:
                    d = os.path.join(tmp, f"{scene}-{ratio}-{snr}")
                    k = max(int(round(ratio * lit)), ks)
                    kp = k - ks + 1
                    noise = noise_flags(snr)
                    run([first, "simulate", *flags, "--size", sizes[scene], "--pulse-len",
                         str(kp), "--seed", str(args.seed), *noise, "--out", d, "--quiet",
                         "--force"], "simulate")
                    truth = np.load(f"{d}/scene.npy")
                    photon = args.photon_model and snr is not None and snr.startswith("photons=")
                    extra = ["--noise", "photon"] if photon else []
                    for label, binary in bins:
                        r = reconstruct(binary, d, ks, truth, extra)
                        results[(scene, label, ratio, snr)] = (k, lit) + r
                        print(f"{scene} {label} {ratio}/lit {column(snr, photon)}: K {k}, "
                              f"exact {r[0]}%, "
                              f"within one {r[1]}%, false {r[2]}% of empty, {r[3]:.1f} s",
                              file=sys.stderr, flush=True)
    for scene in args.scenes.split(","):
        for label, _ in bins:
            print(f"\n### {scene}, {sizes[scene]}, {label}\n")
            print("exact % / within one bin % / false % of empty / seconds\n")
            head = " | ".join(column(s, args.photon_model) for s in snrs)
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
