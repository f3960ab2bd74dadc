#!/usr/bin/env python3
"""What other entropy coders would make of a .mlfeh v2/v3 file's streams (issue #23: is the
lossless file as small as it could be?).

Reads the sections (docs/mlfeh-v3.md), decodes the per-level value codes (zigzag LEB128) and
marks, and compresses them other ways: the file as written (one zstd -19 frame per section),
all value codes in one stream (zstd -19, zstd --ultra -22 --long, xz -9e), the codes split into
byte planes (low byte, high bytes), and the order-0 entropy of the codes per level (what an
adaptive arithmetic coder with the level as its only context would reach, tables not counted).

Usage: /usr/bin/python3 bench/py/mlfeh_streams.py FILE.mlfeh [FILE ...]
"""
import collections
import math
import struct
import subprocess
import sys


def sections(data):
    pos = 16
    while pos < len(data):
        tag, codec, stored, raw, _crc = struct.unpack_from("<4sIQQI", data, pos)
        payload = data[pos + 28:pos + 28 + stored]
        if codec == 1:
            payload = subprocess.run(["zstd", "-d", "-q", "-c"], input=payload, check=True,
                                     capture_output=True).stdout
        yield tag.decode(), 28 + stored, payload
        pos += 28 + stored


def varints(buf, pos, count):
    out = []
    for _ in range(count):
        z, shift = 0, 0
        while True:
            b = buf[pos]
            pos += 1
            z |= (b & 0x7F) << shift
            shift += 7
            if not b & 0x80:
                break
        out.append(z)
    return out, pos


def compressed(cmd, data):
    return len(subprocess.run(cmd, input=data, check=True, capture_output=True).stdout)


def values(p, pos, count, coding):
    """The codes of `count` vertices from pos: one stream (coding 1), or for the integer coding
    (3) seven context streams after their u32 lengths, concatenated here."""
    if coding != 3:
        return varints(p, pos, count)[0]
    lengths = struct.unpack_from("<7I", p, pos)
    pos += 28
    out = []
    for n in lengths:
        end = pos + n
        while pos < end:
            z, pos = varints(p, pos, 1)
            out += z
        pos = end
    assert len(out) == count
    return out


def analyse(path):
    data = open(path, "rb").read()
    per_level, marks, file_bytes = [], [], 0
    dim = struct.unpack_from("<I", data, 12)[0]
    coding = 0
    for tag, nbytes, p in sections(data):
        file_bytes += nbytes
        if tag == "HEAD":
            coding = struct.unpack_from("<I", p, 20)[0]
        elif tag == "MESH":
            nv0, ne0 = struct.unpack_from("<II", p, 0)
            pos = 8 + nv0 * 8 * dim + ne0 * 4 * (dim + 1)
            per_level.append(values(p, pos, nv0, coding))
        elif tag == "LEVL":
            _k, n, m = struct.unpack_from("<III", p, 0)
            nb = (n + 7) // 8
            marks.append(p[12:12 + nb])
            per_level.append(values(p, 12 + nb, m, coding))
    codes = [z for lv in per_level for z in lv]
    stream = bytearray()
    for z in codes:
        while z >= 0x80:
            stream.append((z & 0x7F) | 0x80)
            z >>= 7
        stream.append(z)
    stream = bytes(stream)
    low = bytes(z & 0xFF for z in codes)
    high = bytes(min(z >> 8, 255) for z in codes)
    mark_bytes = b"".join(marks)
    entropy_bits = 0.0
    for lv in per_level:
        c = collections.Counter(lv)
        entropy_bits += sum(-k * math.log2(k / len(lv)) for k in c.values())
    rows = [
        ("file as written (zstd -19 per section)", file_bytes),
        ("marks alone, zstd -19", compressed(["zstd", "-19", "-q", "-c"], mark_bytes)),
        ("value codes in one stream, zstd -19", compressed(["zstd", "-19", "-q", "-c"], stream)),
        ("value codes, zstd --ultra -22 --long=27", compressed(["zstd", "--ultra", "-22", "--long=27", "-q", "-c"],
                                                              stream)),
        ("value codes, xz -9e", compressed(["xz", "-9e", "-c"], stream)),
        ("value codes as byte planes (low, high), zstd -19 each",
         compressed(["zstd", "-19", "-q", "-c"], low) + compressed(["zstd", "-19", "-q", "-c"], high)),
        ("value codes, order-0 entropy per level (ideal arithmetic coder)", int(entropy_bits / 8)),
    ]
    print(f"\n{path}: {len(codes)} values, {sum(len(m) for m in marks)} mark bytes\n")
    print("| stream | bytes |")
    print("|---|---|")
    for name, b in rows:
        print(f"| {name} | {b} |")


if __name__ == "__main__":
    for p in sys.argv[1:]:
        analyse(p)
