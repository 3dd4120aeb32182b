#!/usr/bin/env python3
"""Writes tests/fixtures/import/python.ld, a MoTeC i2 .ld log written from
the reverse-engineered layout (as documented by gotzl/ldparser, and read by
the motec-i2 crate) with Python's struct module: nothing of tirewear's or
the crate's writer is used. Its golden, tests/golden/import-python-ld.json,
holds every channel's decoded values, value = (raw / scale * 10^-dec +
shift) * mul, computed here.

Channels exercise what the crate's own writer never writes: int16, int32
and float32 samples, a scale other than 1, a non-zero shift (offset), and
three sample rates (50, 10 and 2 Hz).

Plain Python (struct, json): python3 tests/oracles/write_motec_ld.py
"""
import json
import math
import struct

META_AT = 0x0800          # channel metadata blocks from here (any offset works)
ENTRY = 124               # bytes per channel metadata block


def text(s, n):
    b = s.encode("ascii")
    assert len(b) < n
    return b + b"\0" * (n - len(b))


def header(n_channels, meta_ptr, data_ptr):
    h = bytearray(1762)
    struct.pack_into("<IIII", h, 0, 0x40, 0, meta_ptr, data_ptr)
    struct.pack_into("<I", h, 36, 0)                 # no event block
    struct.pack_into("<HHH", h, 64, 0, 0x4240, 0x000F)
    struct.pack_into("<I", h, 70, 12345)             # device serial
    h[74:82] = text("ADL3", 8)
    struct.pack_into("<HH", h, 82, 150, 0x0080)
    struct.pack_into("<II", h, 86, n_channels, 0x00010064)
    h[94:110] = text("17/06/2026", 16)
    h[126:142] = text("10:15:30", 16)
    h[158:222] = text("Py Driver", 64)
    h[222:286] = text("car1", 64)
    h[350:414] = text("Nordkamm", 64)
    h[1508:1572] = text("FP2", 64)
    h[1572:1636] = text("written by struct", 64)
    return h


# name, unit, rate Hz, (type, size), shift, mul, scale, dec, raw values
def channels():
    n50, n10, n2 = 100, 20, 4
    return [
        ("Ground Speed", "km/h", 50, (3, 4), 0, 1, 1, 3,
         [int(round((150.0 + 20.0 * math.sin(0.1 * i)) * 1000)) for i in range(n50)]),
        ("G Force Lat", "G", 50, (7, 4), 0, 1, 1, 0,
         # stored as float32: the golden decodes the rounded value
         [struct.unpack("<f", struct.pack("<f", 1.5 * math.sin(0.2 * i)))[0] for i in range(n50)]),
        ("Wheel Speed FL", "km/h", 50, (3, 2), 0, 1, 2, 1,
         [int(round((150.0 + 0.1 * i) * 20)) for i in range(n50)]),
        ("Tyre Temp FL Centre", "C", 10, (3, 2), -40, 1, 1, 1,
         [int(round((85.0 + 0.3 * i + 40) * 10)) for i in range(n10)]),
        ("TPMS Pressure FL", "bar", 2, (3, 2), 0, 2, 1, 3,
         [int(round((1.75 + 0.01 * i) / 2 * 1000)) for i in range(n2)]),
    ]


def decode(raw, shift, mul, scale, dec):
    return (raw / scale * 10.0 ** -dec + shift) * mul


def main():
    chans = channels()
    data_at = META_AT + ENTRY * len(chans)
    body = bytearray()
    metas = []
    for k, (name, unit, rate, (typ, size), shift, mul, scale, dec, raw) in enumerate(chans):
        fmt = {(3, 2): "<h", (3, 4): "<i", (7, 4): "<f"}[(typ, size)]
        addr = data_at + len(body)
        for v in raw:
            body += struct.pack(fmt, v)
        prev_ = META_AT + ENTRY * (k - 1) if k else 0
        next_ = META_AT + ENTRY * (k + 1) if k + 1 < len(chans) else 0
        m = bytearray(ENTRY)
        struct.pack_into("<IIIIHHHHhHHh", m, 0, prev_, next_, addr, len(raw), 4, typ, size, rate,
                         shift, mul, scale, dec)
        m[32:64] = text(name, 32)
        m[64:72] = text(name.replace(" ", "")[:7], 8)
        m[72:84] = text(unit, 12)
        metas.append(m)
    out = header(len(chans), META_AT, data_at)
    out += b"\0" * (META_AT - len(out))
    for m in metas:
        out += m
    out += body
    with open("tests/fixtures/import/python.ld", "wb") as f:
        f.write(out)
    gold = dict(
        venue="Nordkamm", vehicle="car1", driver="Py Driver", date="2026-06-17",
        time_of_day_s=10 * 3600 + 15 * 60 + 30,
        channels=[dict(name=c[0], unit=c[1], rate_hz=c[2],
                       values=[decode(v, c[4], c[5], c[6], c[7]) for v in c[8]]) for c in chans],
    )
    with open("tests/golden/import-python-ld.json", "w") as f:
        json.dump(gold, f, indent=1)


if __name__ == "__main__":
    main()
