#!/usr/bin/env python3
"""Writes the generated seeds of the png and exr corpora (tests/fuzz/corpus/{png,exr}/).

Small images in every variant the readers accept, so the fuzzers start from each code path:
PNG colour types 0, 2, 3, 4, 6 at 8 and 16 bits and one Adam7-interlaced file; EXR scan-line
files in HALF, FLOAT and UINT, RGB, RGBA and Y-only, NONE, RLE, ZIPS and ZIP compression,
decreasing line order and an offset data window, and one tiled file. Written by hand (zlib and
struct only) so that the seeds need no image library; run from anywhere:
    python3 tests/fuzz/make_seeds.py
"""
import os
import struct
import zlib

HERE = os.path.dirname(os.path.abspath(__file__))


# --- PNG -----------------------------------------------------------------------------------------

def png_chunk(kind, data):
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def png(width, height, bit_depth, colour_type, rows, palette=None, interlace=0):
    """rows: one bytes object per scan line (without filter byte), or for interlace=1 the
    already-filtered Adam7 stream."""
    ihdr = struct.pack(">IIBBBBB", width, height, bit_depth, colour_type, 0, 0, interlace)
    raw = rows if interlace else b"".join(b"\x00" + r for r in rows)
    out = b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", ihdr)
    if palette:
        out += png_chunk(b"PLTE", palette)
    out += png_chunk(b"IDAT", zlib.compress(raw, 9)) + png_chunk(b"IEND", b"")
    return out


def write_pngs(folder):
    w, h = 4, 3
    channels = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}
    names = {0: "gray", 2: "rgb", 3: "palette", 4: "gray_alpha", 6: "rgba"}
    for colour_type, n in channels.items():
        for depth in (8, 16):
            if colour_type == 3 and depth == 16:
                continue
            rows = []
            for y in range(h):
                row = b""
                for x in range(w):
                    for c in range(n):
                        v = (x * 60 + y * 40 + c * 25) % 256
                        if colour_type == 3:
                            v %= 4
                        row += bytes([v]) if depth == 8 else struct.pack(">H", v * 257)
                rows.append(row)
            palette = bytes([0, 0, 0, 255, 0, 0, 0, 255, 0, 0, 0, 255]) if colour_type == 3 else None
            data = png(w, h, depth, colour_type, rows, palette)
            open(os.path.join(folder, f"{names[colour_type]}{depth}.png"), "wb").write(data)
    # Adam7, 8-bit gray, 8x8: seven passes, each a sub-image with its own filter bytes.
    passes = [(0, 0, 8, 8), (4, 0, 8, 8), (0, 4, 4, 8), (2, 0, 4, 4), (0, 2, 2, 4), (1, 0, 2, 2), (0, 1, 1, 2)]
    stream = b""
    for x0, y0, dx, dy in passes:
        for y in range(y0, 8, dy):
            stream += b"\x00" + bytes((x * 30 + y * 7) % 256 for x in range(x0, 8, dx))
    open(os.path.join(folder, "gray8_interlaced.png"), "wb").write(png(8, 8, 8, 0, stream, interlace=1))


# --- EXR -----------------------------------------------------------------------------------------

HALF, UINT, FLOAT = 1, 0, 2
NONE, RLE, ZIPS, ZIP = 0, 1, 2, 3


def attr(name, kind, data):
    return name.encode() + b"\0" + kind.encode() + b"\0" + struct.pack("<i", len(data)) + data


def chlist(channels):
    out = b""
    for name, kind in sorted(channels):
        out += name.encode() + b"\0" + struct.pack("<iB3xii", kind, 0, 1, 1)
    return out + b"\0"


def value_bytes(kind, v):
    if kind == HALF:
        return struct.pack("<e", v)
    if kind == FLOAT:
        return struct.pack("<f", v)
    return struct.pack("<I", int(v * 100))


def exr_predict_and_interleave(raw):
    # OpenEXR's ZIP/RLE preprocessing: split even and odd bytes, then delta-encode.
    split = raw[0::2] + raw[1::2]
    out = bytearray(split)
    for i in range(len(out) - 1, 0, -1):
        out[i] = (split[i] - split[i - 1] + 128 + 256) % 256
    return bytes(out)


def exr_rle(data):
    out = bytearray()
    i = 0
    while i < len(data):
        run = 1
        while i + run < len(data) and data[i + run] == data[i] and run < 128:
            run += 1
        if run >= 3:
            out += struct.pack("b", run - 1) + data[i:i + 1]
            i += run
        else:
            j = i
            while j < len(data) and j - i < 127 and not (j + 2 < len(data) and data[j] == data[j + 1] == data[j + 2]):
                j += 1
            out += struct.pack("b", -(j - i)) + data[i:j]
            i = j
    return bytes(out)


def compress(compression, raw):
    if compression == NONE:
        return raw
    pre = exr_predict_and_interleave(raw)
    packed = exr_rle(pre) if compression == RLE else zlib.compress(pre, 9)
    return packed if len(packed) < len(raw) else raw


def exr(width, height, channels, compression=NONE, origin=(0, 0), decreasing=False, tile=None):
    x0, y0 = origin
    box = struct.pack("<iiii", x0, y0, x0 + width - 1, y0 + height - 1)
    header = (attr("channels", "chlist", chlist(channels))
              + attr("compression", "compression", bytes([compression]))
              + attr("dataWindow", "box2i", box)
              + attr("displayWindow", "box2i", box)
              + attr("lineOrder", "lineOrder", bytes([1 if decreasing else 0]))
              + attr("pixelAspectRatio", "float", struct.pack("<f", 1.0))
              + attr("screenWindowCenter", "v2f", struct.pack("<ff", 0.0, 0.0))
              + attr("screenWindowWidth", "float", struct.pack("<f", 1.0)))
    if tile:
        header += attr("tiles", "tiledesc", struct.pack("<IIB", tile, tile, 0))
    header += b"\0"
    version = struct.pack("<I", 2 | (0x200 if tile else 0))
    start = 4 + 4 + len(header)

    def row_bytes(y, xs):
        out = b""
        for name, kind in sorted(channels):
            for x in xs:
                # Compressed variants get rows of one value, so that compression pays (a chunk
                # that would not shrink must be stored raw, and the decoder would not run).
                v = 0.25 * (y % 3) if compression != NONE else ((x + 2 * y) % 7) / 6.0
                out += value_bytes(kind, v + (0.5 if name == "G" else 0.0))
        return out

    chunks = []
    if tile:
        for ty in range(0, height, tile):
            for tx in range(0, width, tile):
                raw = b"".join(row_bytes(y, range(tx, min(tx + tile, width)))
                               for y in range(ty, min(ty + tile, height)))
                data = compress(compression, raw)
                chunks.append(struct.pack("<iiiii", tx // tile, ty // tile, 0, 0, len(data)) + data)
    else:
        lines = 16 if compression == ZIP else 1
        order = range(0, height, lines)
        for y in order:
            raw = b"".join(row_bytes(yy, range(width)) for yy in range(y, min(y + lines, height)))
            data = compress(compression, raw)
            chunks.append((y, struct.pack("<ii", y0 + y, len(data)) + data))
        if decreasing:
            chunks.reverse()
        # The offset table is indexed by chunk position in y, whatever the order in the file.
        positions, offset, body = {}, start + 8 * len(chunks), b""
        for y, c in chunks:
            positions[y] = offset + len(body)
            body += c
        table = b"".join(struct.pack("<Q", positions[y]) for y in order)
        return b"\x76\x2f\x31\x01" + version + header + table + body
    table, offset = b"", start + 8 * len(chunks)
    for c in chunks:
        table += struct.pack("<Q", offset)
        offset += len(c)
    return b"\x76\x2f\x31\x01" + version + header + table + b"".join(chunks)


def write_exrs(folder):
    rgb = lambda kind: [("R", kind), ("G", kind), ("B", kind)]
    files = {
        "half_rgb_none.exr": exr(4, 3, rgb(HALF)),
        "float_rgb_none.exr": exr(4, 3, rgb(FLOAT)),
        "uint_rgb_none.exr": exr(4, 3, rgb(UINT)),
        "half_rgba_rle.exr": exr(5, 4, rgb(HALF) + [("A", HALF)], RLE),
        "float_y_zips.exr": exr(4, 4, [("Y", FLOAT)], ZIPS),
        "half_rgb_zip.exr": exr(6, 5, rgb(HALF), ZIP),
        "float_rgb_decreasing_offset.exr": exr(3, 4, rgb(FLOAT), NONE, origin=(-2, 5), decreasing=True),
        "half_rgb_tiled.exr": exr(5, 5, rgb(HALF), NONE, tile=4),
    }
    for name, data in files.items():
        open(os.path.join(folder, name), "wb").write(data)


if __name__ == "__main__":
    for reader, write in (("png", write_pngs), ("exr", write_exrs)):
        folder = os.path.join(HERE, "corpus", reader)
        os.makedirs(folder, exist_ok=True)
        write(folder)
