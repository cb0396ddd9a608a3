#!/usr/bin/env python3
"""Converts the binary PPM (P6, maxval 255) frames that `monolith run` writes into PNG files for
the documentation, with nothing but the Python standard library (zlib for the image data).
    python3 tests/tools/ppm_to_png.py IN.ppm OUT.png [IN2.ppm OUT2.png ...]
Not part of the build: the project itself writes PPM only (docs/rendering.md)."""
import struct
import sys
import zlib


def read_ppm(path):
    data = open(path, "rb").read()
    fields, pos = [], 0
    # header: magic, width, height, maxval, separated by whitespace, with # comments
    while len(fields) < 4:
        while data[pos:pos + 1].isspace():
            pos += 1
        if data[pos:pos + 1] == b"#":
            pos = data.index(b"\n", pos) + 1
            continue
        end = pos
        while not data[end:end + 1].isspace():
            end += 1
        fields.append(data[pos:end])
        pos = end
    pos += 1  # the single whitespace byte after maxval
    if fields[0] != b"P6" or int(fields[3]) != 255:
        raise SystemExit(f"{path}: not a P6 PPM with maxval 255")
    width, height = int(fields[1]), int(fields[2])
    pixels = data[pos:pos + 3 * width * height]
    if len(pixels) != 3 * width * height:
        raise SystemExit(f"{path}: truncated pixel data")
    return width, height, pixels


def chunk(kind, body):
    return (struct.pack(">I", len(body)) + kind + body +
            struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF))


def write_png(path, width, height, pixels):
    row = 3 * width
    # filter type 0 (none) before every row
    raw = b"".join(b"\x00" + pixels[y * row:(y + 1) * row] for y in range(height))
    png = (b"\x89PNG\r\n\x1a\n" +
           chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)) +
           chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))
    open(path, "wb").write(png)


def main(args):
    if len(args) < 2 or len(args) % 2:
        raise SystemExit(__doc__)
    for src, dst in zip(args[0::2], args[1::2]):
        write_png(dst, *read_ppm(src))


if __name__ == "__main__":
    main(sys.argv[1:])
