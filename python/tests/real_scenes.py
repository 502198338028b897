"""A test set of depth maps the reconstructions have not been tuned on: a real one (the
Middlebury motorcycle's disparity that scikit-image ships, as depth, three windows of it) and
drawn ones (a sphere before a slanted wall, a staircase on a sloping floor). Each is a float
map of depth fractions in (0, 1] (0 nearest, 1 the farthest bin), NaN where there is no
return, written as the 16-bit PNG depth maps that ``simulate --depth-png`` reads (v = 0 no
return, v / 65535 · (K_s − 1) bins).
"""

import zlib
import struct

import numpy as np


def _block_mean(a, m, n):
    """`a` averaged over an m × n grid of blocks, NaN where more than half a block is NaN."""
    h, w = a.shape
    rows = np.linspace(0, h, m + 1).astype(int)
    cols = np.linspace(0, w, n + 1).astype(int)
    out = np.full((m, n), np.nan)
    for i in range(m):
        for j in range(n):
            b = a[rows[i]:rows[i + 1], cols[j]:cols[j + 1]]
            ok = np.isfinite(b)
            if ok.mean() > 0.5:
                out[i, j] = b[ok].mean()
    return out


def _motorcycle(m, n, window):
    from skimage import data
    _, _, disparity = data.stereo_motorcycle()
    disparity = np.where(np.isfinite(disparity) & (disparity > 0), disparity, np.nan)
    r0, r1, c0, c1 = window
    depth = 1.0 / _block_mean(disparity[r0:r1, c0:c1], m, n)
    lo, hi = np.nanmin(depth), np.nanmax(depth)
    return 0.05 + 0.9 * (depth - lo) / (hi - lo)


def _sphere(m, n):
    i, j = np.mgrid[0:m, 0:n]
    u, v = (j + 0.5) / n, (i + 0.5) / m
    wall = 0.55 + 0.3 * u + 0.1 * v
    r2 = ((u - 0.45) ** 2 + (v - 0.55) ** 2) / 0.28 ** 2
    ball = 0.3 - 0.2 * np.sqrt(np.clip(1 - r2, 0, None))
    depth = np.where(r2 < 1, ball, wall)
    # The sky above a horizon in the top-right corner: no return.
    return np.where((v < 0.18) & (u > 0.55), np.nan, depth)


def _stairs(m, n):
    i, j = np.mgrid[0:m, 0:n]
    u, v = (j + 0.5) / n, (i + 0.5) / m
    steps = np.floor(u * 5) / 5
    depth = 0.12 + 0.7 * steps + 0.15 * v + 0.037
    # An empty doorway.
    return np.where((u > 0.72) & (u < 0.86) & (v < 0.45), np.nan, depth)


def scenes(m, n):
    """The test set at m × n pixels: name → depth fractions in (0, 1], NaN for no return."""
    return {
        "motorcycle": _motorcycle(m, n, (0, 500, 120, 620)),
        "motorcycle-left": _motorcycle(m, n, (150, 450, 0, 300)),
        "motorcycle-right": _motorcycle(m, n, (100, 400, 420, 720)),
        "sphere": _sphere(m, n),
        "stairs": _stairs(m, n),
    }


def write_depth_png(path, fraction):
    """A 16-bit grayscale PNG of the depth fractions (0 where NaN)."""
    v = np.where(np.isnan(fraction), 0, np.clip(np.rint(fraction * 65535), 1, 65535))
    image = v.astype(">u2")
    h, w = image.shape

    def chunk(kind, payload):
        return (struct.pack(">I", len(payload)) + kind + payload
                + struct.pack(">I", zlib.crc32(kind + payload) & 0xFFFFFFFF))

    raw = b"".join(b"\x00" + image[r].tobytes() for r in range(h))
    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n"
                + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 16, 0, 0, 0, 0))
                + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))
