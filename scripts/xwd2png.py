#!/usr/bin/env python3
"""Converts an X window dump (`xwd` output, 24/32-bit TrueColor) to PNG, and says whether the
picture is blank (one colour), with no image library: ImageMagick is not always installed.

    xwd2png.py IN.xwd OUT.png [--crop X,Y,W,H] [--zoom N]

Prints "WxH, N colours" and exits 2 if the (cropped) picture has a single colour."""
import struct
import sys
import zlib


def read_xwd(path):
    data = open(path, "rb").read()
    header = struct.unpack(">25I", data[:100])
    (header_size, version, _format, _depth, width, height, _xoff, byte_order, _unit, _bit_order,
     _pad, bits_per_pixel, bytes_per_line, _class, red_mask, green_mask, blue_mask, _bits_rgb,
     _entries, ncolors) = header[:20]
    if version != 7 or bits_per_pixel not in (24, 32):
        sys.exit(f"{path}: not a 24/32-bit XWD (version {version}, {bits_per_pixel} bpp)")
    start = header_size + 12 * ncolors
    step = bits_per_pixel // 8
    order = "<" if byte_order == 0 else ">"
    shifts = [(mask, (mask & -mask).bit_length() - 1) for mask in (red_mask, green_mask, blue_mask)]
    rows = []
    for y in range(height):
        line = data[start + y * bytes_per_line:start + y * bytes_per_line + width * step]
        if step == 4:
            pixels = struct.unpack(f"{order}{width}I", line)
        else:
            pixels = [int.from_bytes(line[i:i + 3], "little" if order == "<" else "big")
                      for i in range(0, len(line), 3)]
        row = bytearray()
        for p in pixels:
            for mask, shift in shifts:
                row.append((p & mask) >> shift)
        rows.append(bytes(row))
    return width, height, rows


def write_png(path, width, height, rows):
    def chunk(kind, body):
        return (struct.pack(">I", len(body)) + kind + body
                + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF))
    raw = b"".join(b"\0" + row for row in rows)
    with open(path, "wb") as out:
        out.write(b"\x89PNG\r\n\x1a\n")
        out.write(chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)))
        out.write(chunk(b"IDAT", zlib.compress(raw, 6)))
        out.write(chunk(b"IEND", b""))


def main():
    args = sys.argv[1:]
    crop = None
    if "--crop" in args:
        at = args.index("--crop")
        crop = [int(v) for v in args[at + 1].split(",")]
        del args[at:at + 2]
    zoom = 1
    if "--zoom" in args:
        at = args.index("--zoom")
        zoom = int(args[at + 1])
        del args[at:at + 2]
    if len(args) != 2:
        sys.exit(__doc__)
    width, height, rows = read_xwd(args[0])
    if crop:
        x, y, w, h = crop
        rows = [row[3 * x:3 * (x + w)] for row in rows[y:y + h]]
        width, height = w, h
    colours = {row[i:i + 3] for row in rows[::4] for i in range(0, len(row), 12)}
    if zoom > 1:
        # Nearest neighbour, to look at a few pixels closely.
        rows = [b"".join(row[i:i + 3] * zoom for i in range(0, len(row), 3))
                for row in rows for _ in range(zoom)]
    write_png(args[1], width * zoom, height * zoom, rows)
    print(f"{width}x{height}, {len(colours)} colours")
    sys.exit(2 if len(colours) <= 1 else 0)


if __name__ == "__main__":
    main()
