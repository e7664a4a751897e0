#!/usr/bin/env python3
# Puts 8-bit RGB/RGBA PNGs (non-interlaced) side by side, separated by an 8-pixel white gap, into one RGB PNG.
# Python standard library only. Made docs/images/bonsai_network_vs_ground_truth.png:
#   python3 scripts/side_by_side.py OUT.png network.png ground_truth.png
import struct, sys, zlib

def read_png(path):
    data = open(path, "rb").read()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", path
    pos, idat = 8, b""
    while pos < len(data):
        n, typ = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + n]
        if typ == b"IHDR":
            w, h, depth, ctype, _, _, interlace = struct.unpack(">IIBBBBB", body)
            assert depth == 8 and ctype in (2, 6) and interlace == 0, (depth, ctype, interlace)
        elif typ == b"IDAT":
            idat += body
        pos += 12 + n
    bpp = 3 if ctype == 2 else 4
    raw, stride = zlib.decompress(idat), w * bpp
    rows, prev = [], bytearray(stride)
    for y in range(h):
        f, line = raw[y * (stride + 1)], bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - bpp] if i >= bpp else 0
            b, c = prev[i], prev[i - bpp] if i >= bpp else 0
            if f == 1: line[i] = (line[i] + a) & 255
            elif f == 2: line[i] = (line[i] + b) & 255
            elif f == 3: line[i] = (line[i] + (a + b) // 2) & 255
            elif f == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        rows.append(bytes(line[j] for j in range(stride) if j % bpp < 3))  # drop alpha
        prev = line
    return w, h, rows

def write_png(path, w, h, rows):
    def chunk(t, b): return struct.pack(">I", len(b)) + t + b + struct.pack(">I", zlib.crc32(t + b) & 0xffffffff)
    raw = b"".join(b"\x00" + r for r in rows)
    open(path, "wb").write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
                           + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))

out, gap = sys.argv[1], 8
imgs = [read_png(p) for p in sys.argv[2:]]
h = max(i[1] for i in imgs)
w = sum(i[0] for i in imgs) + gap * (len(imgs) - 1)
rows = []
for y in range(h):
    parts = []
    for k, (iw, ih, r) in enumerate(imgs):
        parts.append(r[y] if y < ih else bytes(3 * iw))
        if k + 1 < len(imgs): parts.append(bytes([255]) * (3 * gap))
    rows.append(b"".join(parts))
write_png(out, w, h, rows)
