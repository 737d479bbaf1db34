#!/usr/bin/env python3
"""A large voxel-art scene made by tiling a bundled MagicaVoxel model, for timing the
clamped (voxel-art) solve beyond the bundled sizes.

Reads the first model of a ``.vox`` file (its SIZE and XYZI chunks), repeats it
``NX x NY x NZ`` times with a two-voxel gap, every other copy mirrored along x so the
copies are not all alike, and writes the labels as a ``.npy`` (uint8, shape (X, Y, Z)).
Run voxreg on it with the voxel-art preset, as it runs on ``.vox`` files:

    python3 bench/speed/tile_vox.py data/veh_fire.vox 4 2 2 target/bench/fire16.npy     # 96k quads
    voxreg regularize target/bench/fire16.npy --preset voxel-art -o out.ply --report r.json

Standard library only.
"""

import struct
import sys


def read_first_model(path):
    data = open(path, "rb").read()
    if data[:4] != b"VOX ":
        sys.exit(f"{path}: not a MagicaVoxel file")
    pos, size, voxels = 8, None, None
    # MAIN's header, then its children, each: id, content bytes, children bytes.
    pos += 12
    while pos + 12 <= len(data) and voxels is None:
        cid, n, m = data[pos : pos + 4], *struct.unpack_from("<ii", data, pos + 4)
        body = data[pos + 12 : pos + 12 + n]
        if cid == b"SIZE":
            size = struct.unpack_from("<iii", body)
        elif cid == b"XYZI":
            (count,) = struct.unpack_from("<i", body)
            voxels = [tuple(body[4 + 4 * k : 8 + 4 * k]) for k in range(count)]
        pos += 12 + n + m
    if size is None or voxels is None:
        sys.exit(f"{path}: no model")
    return size, voxels


def main():
    if len(sys.argv) != 6:
        sys.exit("usage: tile_vox.py IN.vox NX NY NZ OUT.npy")
    (sx, sy, sz), voxels = read_first_model(sys.argv[1])
    nx, ny, nz = (int(a) for a in sys.argv[2:5])
    gap = 2
    dims = (nx * (sx + gap), ny * (sy + gap), nz * (sz + gap))
    grid = bytearray(dims[0] * dims[1] * dims[2])
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                mirror = (i + j + k) % 2 == 1
                for x, y, z, c in voxels:
                    gx = i * (sx + gap) + (sx - 1 - x if mirror else x)
                    gy, gz = j * (sy + gap) + y, k * (sz + gap) + z
                    grid[(gx * dims[1] + gy) * dims[2] + gz] = c
    header = "{'descr': '|u1', 'fortran_order': False, 'shape': (%d, %d, %d), }" % dims
    header += " " * ((64 - (len(header) + 11) % 64) % 64) + "\n"
    with open(sys.argv[5], "wb") as f:
        f.write(b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode())
        f.write(grid)


if __name__ == "__main__":
    main()
