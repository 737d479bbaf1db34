"""Writes the small format samples of data/formats/ with each format's own Python tool
(tifffile, pynrrd, mrcfile, zarr).

Made with:  python3 -m venv target/formats-venv
            target/formats-venv/bin/pip install numpy tifffile pynrrd mrcfile zarr
            target/formats-venv/bin/python data/formats/make.py
(with numpy 2.4.6, tifffile 2026.3.3, pynrrd 1.1.3, mrcfile 1.5.4; the Zarr samples,
`make.py zarr`, with zarr 3.1.6 and numcodecs 0.16.6). Every sample holds the same
6 x 5 x 4 volume `labels()`, indexed [x, y, z]: label 1, a 3 x 3 x 2 block, and label 2, a
2 x 2 x 2 block, in background 0. The tools store arrays z-slowest ([z, y, x]), so each
array below is `labels().transpose()`.
"""

import json
import os
import shutil
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))


def labels():
    a = np.zeros((6, 5, 4), dtype=np.uint8)
    a[1:4, 1:4, 1:3] = 1
    a[3:5, 2:4, 2:4] = 2
    return a


def tiffs(zyx):
    import tifffile

    # ImageJ hyperstack: spacing 0.5 x 0.5 x 2 micron (x, y from the resolution tags).
    tifffile.imwrite(
        f"{HERE}/stack_imagej.tif", zyx.astype(np.uint16), imagej=True,
        resolution=(2.0, 2.0), metadata={"spacing": 2.0, "unit": "micron", "axes": "ZYX"},
    )
    # OME-TIFF, 32-bit, deflate-compressed: spacing 0.25 x 0.25 x 1 µm.
    tifffile.imwrite(
        f"{HERE}/stack.ome.tif", zyx.astype(np.uint32), compression="zlib",
        metadata={"axes": "ZYX", "PhysicalSizeX": 0.25, "PhysicalSizeY": 0.25, "PhysicalSizeZ": 1.0},
    )
    # A directory of single-page 8-bit slices, uncompressed.
    d = f"{HERE}/slices"
    shutil.rmtree(d, ignore_errors=True)
    os.makedirs(d)
    for z, page in enumerate(zyx):
        tifffile.imwrite(f"{d}/slice_{z:03}.tif", page)


def nrrds(zyx):
    import nrrd

    xyz = zyx.transpose()
    header = {
        "space": "right-anterior-superior",
        "space directions": np.diag([0.5, 0.5, 1.5]),
        "space origin": np.array([10.0, -4.0, 2.5]),
        "space units": ["mm", "mm", "mm"],
        "encoding": "gzip",
    }
    nrrd.write(f"{HERE}/labels.nrrd", xyz.astype(np.int16), header, index_order="F")
    # Detached header and raw data.
    raw = dict(header, encoding="raw")
    nrrd.write(f"{HERE}/detached.nhdr", xyz.astype(np.uint8), raw, detached_header=True, index_order="F")
    # 3D Slicer segmentation: segment names, label values and colours in the header.
    seg = dict(header, encoding="gzip")
    for k, (name, value, color) in enumerate([("liver", 1, "0.8 0.2 0.2"), ("spleen", 2, "0.2 0.4 0.9")]):
        seg[f"Segment{k}_Name"] = name
        seg[f"Segment{k}_LabelValue"] = str(value)
        seg[f"Segment{k}_Layer"] = "0"
        seg[f"Segment{k}_Color"] = color
        seg[f"Segment{k}_ID"] = f"Segment_{k + 1}"
    nrrd.write(f"{HERE}/organs.seg.nrrd", xyz.astype(np.uint8), seg, index_order="F")


def mrcs(zyx):
    import mrcfile

    for mode, dtype in [(0, np.int8), (1, np.int16), (6, np.uint16)]:
        with mrcfile.new(f"{HERE}/mode{mode}.mrc", overwrite=True) as m:
            m.set_data(zyx.astype(dtype))
            m.voxel_size = (1.5, 1.5, 3.0)  # x, y, z in Å
    # .map: the same format, a common name for maps.
    shutil.copy(f"{HERE}/mode1.mrc", f"{HERE}/labels.map")


def zarrs(zyx):
    import numcodecs
    import zarr
    from zarr.codecs import GzipCodec, ZstdCodec

    def array(path, data, **kw):
        shutil.rmtree(path, ignore_errors=True)
        z = zarr.create_array(store=path, shape=data.shape, dtype=data.dtype, fill_value=0, **kw)
        z[...] = data

    # Zarr v2, blosc (lz4, byte shuffle); chunks that do not divide the shape.
    array(f"{HERE}/labels_v2.zarr", zyx.astype(np.uint16), chunks=(2, 3, 4), zarr_format=2,
          compressors=numcodecs.Blosc(cname="lz4", clevel=5, shuffle=numcodecs.Blosc.SHUFFLE))
    # Zarr v3, zstd.
    array(f"{HERE}/labels_v3.zarr", zyx.astype(np.uint16), chunks=(2, 3, 4), zarr_format=3,
          compressors=ZstdCodec(level=3))
    # Zarr v3, sharded (shards of 2 x 2 chunks of 2 x 3 x 3), gzip, 32-bit.
    array(f"{HERE}/labels_sharded.zarr", zyx.astype(np.int32), chunks=(2, 3, 3), shards=(4, 6, 6),
          zarr_format=3, compressors=GzipCodec(level=5))

    # OME-Zarr images: two levels, level 0 at 0.5 x 0.5 x 2 micrometer (x, y, z); 0.4 on
    # Zarr v2 (multiscales in the group's attributes), 0.5 on Zarr v3 (under "ome").
    levels = [(zyx, [2.0, 0.5, 0.5]), (np.ascontiguousarray(zyx[::2, ::2, ::2]), [4.0, 1.0, 1.0])]
    for version, zarr_format, name in [("0.4", 2, "image.ome.zarr"), ("0.5", 3, "image_v3.ome.zarr")]:
        path = f"{HERE}/{name}"
        shutil.rmtree(path, ignore_errors=True)
        root = zarr.open_group(path, mode="w", zarr_format=zarr_format)
        for level, (data, _) in enumerate(levels):
            a = root.create_array(str(level), shape=data.shape, chunks=(2, 2, 2), dtype="uint8", fill_value=0)
            a[...] = data
        multiscales = [{
            "axes": [{"name": n, "type": "space", "unit": "micrometer"} for n in "zyx"],
            "datasets": [
                {"path": str(level), "coordinateTransformations": [{"type": "scale", "scale": scale}]}
                for level, (_, scale) in enumerate(levels)
            ],
        }]
        if version == "0.4":
            multiscales[0]["version"] = version
            root.attrs["multiscales"] = multiscales
        else:
            root.attrs["ome"] = {"version": version, "multiscales": multiscales}


def main():
    formats = sys.argv[1:] or ["tiff", "nrrd", "mrc", "zarr"]
    versions = {"numpy": np.__version__}
    for f, modules in [("tiff", ["tifffile"]), ("nrrd", ["nrrd"]), ("mrc", ["mrcfile"]), ("zarr", ["zarr", "numcodecs"])]:
        if f in formats:
            for m in modules:
                versions[m] = __import__(m).__version__
    print("versions:", json.dumps(versions))
    zyx = np.ascontiguousarray(labels().transpose())
    for f in formats:
        {"tiff": tiffs, "nrrd": nrrds, "mrc": mrcs, "zarr": zarrs}[f](zyx)


if __name__ == "__main__":
    main()
