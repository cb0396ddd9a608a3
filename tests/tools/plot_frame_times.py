#!/usr/bin/env python3
"""Draws seconds per frame against grid cells on log-log axes as a binary PPM, with nothing but the
Python standard library (docs/benchmarks.md, issue 20; convert with tests/tools/ppm_to_png.py).
    python3 tests/tools/plot_frame_times.py OUT.ppm SERIES [SERIES ...]
SERIES is "r,g,b:cells=seconds,cells=seconds,..." (one colour per series, points in any order).
Axes: cells from 1e5 to 1e8, seconds from 0.1 to 1000, a grid line at every power of ten (the
labels are the caption's job: the picture carries no text). A grey dashed line of slope 1 through
the first point of the first series shows cost in proportion to the cells."""
import math
import sys

W, H, M = 640, 480, 50
X0, X1 = 5.0, 8.0    # log10 cells
Y0, Y1 = -1.0, 3.0   # log10 seconds


def to_px(cells, seconds):
    x = M + (math.log10(cells) - X0) / (X1 - X0) * (W - 2 * M)
    y = H - M - (math.log10(seconds) - Y0) / (Y1 - Y0) * (H - 2 * M)
    return x, y


def main():
    out, specs = sys.argv[1], sys.argv[2:]
    img = bytearray([255] * (W * H * 3))

    def put(x, y, c):
        x, y = int(round(x)), int(round(y))
        if 0 <= x < W and 0 <= y < H:
            img[3 * (y * W + x):3 * (y * W + x) + 3] = bytes(c)

    def line(a, b, c, width=1, dash=0):
        n = int(max(abs(b[0] - a[0]), abs(b[1] - a[1]))) + 1
        for i in range(n + 1):
            if dash and (i // dash) % 2:
                continue
            t = i / n
            x, y = a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])
            for dx in range(-(width // 2), width // 2 + 1):
                for dy in range(-(width // 2), width // 2 + 1):
                    put(x + dx, y + dy, c)

    # grid lines at the powers of ten, the frame in black
    for e in range(int(X0), int(X1) + 1):
        x, _ = to_px(10 ** e, 1.0)
        line((x, M), (x, H - M), (210, 210, 210))
    for e in range(int(Y0), int(Y1) + 1):
        _, y = to_px(1e6, 10 ** e)
        line((M, y), (W - M, y), (210, 210, 210))
    line((M, M), (M, H - M), (0, 0, 0))
    line((M, H - M), (W - M, H - M), (0, 0, 0))
    series = []
    for spec in specs:
        colour, points = spec.split(":")
        c = tuple(int(v) for v in colour.split(","))
        pts = sorted((float(a), float(b)) for a, b in (p.split("=") for p in points.split(",")))
        series.append((c, pts))
    if series:
        cells, seconds = series[0][1][0]
        a = to_px(10 ** X0, seconds * 10 ** X0 / cells)
        b = to_px(10 ** X1, seconds * 10 ** X1 / cells)
        line(a, b, (150, 150, 150), dash=6)
    for c, pts in series:
        px = [to_px(*p) for p in pts]
        for a, b in zip(px, px[1:]):
            line(a, b, c, width=3)
        for x, y in px:
            for dx in range(-5, 6):
                for dy in range(-5, 6):
                    put(x + dx, y + dy, c)
    with open(out, "wb") as f:
        f.write(b"P6\n%d %d\n255\n" % (W, H))
        f.write(bytes(img))


if __name__ == "__main__":
    main()
