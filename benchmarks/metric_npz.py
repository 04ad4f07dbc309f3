#!/usr/bin/env python3
"""Rewrites a geographic .npz DEM (matplotlib's scalars xmin, xmax, ymin, ymax, dx, dy in degrees,
as jacksboro_fault_dem.npz) with the same samples in local metres (equirectangular about the
centre latitude, origin at the west/south edge), so that a camera flies in one unit on every
axis. Python's standard library only.  Usage: metric_npz.py IN.npz OUT.npz"""
import io
import math
import struct
import sys
import zipfile


def scalar(data):
    header_len = struct.unpack("<H", data[8:10])[0]
    return struct.unpack("<d", data[10 + header_len:10 + header_len + 8])[0]


def npy_scalar(value):
    header = "{'descr': '<f8', 'fortran_order': False, 'shape': (), }"
    header += " " * (63 - len(header) - 10) + "\n"  # 10 + len(header) = 64
    out = io.BytesIO()
    out.write(b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode())
    out.write(struct.pack("<d", value))
    return out.getvalue()


def main(src, dst):
    zin = zipfile.ZipFile(src)
    s = {n[:-4]: scalar(zin.read(n)) for n in zin.namelist() if n[:-4] in
         ("xmin", "xmax", "ymin", "ymax", "dx", "dy")}
    lat = math.radians(0.5 * (s["ymin"] + s["ymax"]))
    m_per_deg = 6371008.8 * math.pi / 180.0
    sx, sy = m_per_deg * math.cos(lat), m_per_deg
    w, h = abs(s["xmax"] - s["xmin"]) * sx, abs(s["ymax"] - s["ymin"]) * sy
    metric = {"xmin": 0.0, "xmax": w, "ymin": h, "ymax": 0.0, "dx": s["dx"] * sx, "dy": s["dy"] * sy}
    if s["ymin"] < s["ymax"]:
        metric["ymin"], metric["ymax"] = 0.0, h
    with zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as zout:
        for n in zin.namelist():
            key = n[:-4]
            zout.writestr(n, npy_scalar(metric[key]) if key in metric else zin.read(n))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
