"""An independent transcription of COLMAP's model files for the tests: a binary reader (numpy
structured records, unlike the library's struct cursor) and binary and text writers.

Layouts as in COLMAP's src/colmap/scene/reconstruction_io (binary.cc / text.cc). A model here is
plain data: cameras [(id, model_id, width, height, params)], images [(id, qvec, tvec, camera_id,
name, [(x, y, point3D_id)])], points [(id, xyz, rgb, error, [(image_id, point2D_idx)])].
(pycolmap 4.2.1 read the skull model exactly as the library does: a one-off check while writing
the reader, not repeated here because pycolmap is not a test dependency.)
"""

import os
import struct

import numpy as np

MODEL_NAMES = {0: "SIMPLE_PINHOLE", 1: "PINHOLE", 2: "SIMPLE_RADIAL", 3: "RADIAL", 4: "OPENCV",
               6: "FULL_OPENCV"}
NUM_PARAMS = {0: 3, 1: 4, 2: 4, 3: 5, 4: 8, 6: 12}
NO_POINT = 2**64 - 1  # point3D_id of a keypoint with no 3D point (-1 as uint64)


def _take(buf, pos, dtype, count=1):
    out = np.frombuffer(buf, dtype, count, pos)
    return out, pos + out.nbytes


def read_bin(folder):
    """(cameras, images, points) of a binary model."""
    buf = open(os.path.join(folder, "cameras.bin"), "rb").read()
    (n,), pos = _take(buf, 0, "<u8")
    cameras = []
    for _ in range(int(n)):
        (rec,), pos = _take(buf, pos, np.dtype([("id", "<u4"), ("model", "<i4"), ("w", "<u8"),
                                                ("h", "<u8")]))
        params, pos = _take(buf, pos, "<f8", NUM_PARAMS[int(rec["model"])])
        cameras.append((int(rec["id"]), int(rec["model"]), int(rec["w"]), int(rec["h"]),
                        tuple(params.tolist())))
    buf = open(os.path.join(folder, "images.bin"), "rb").read()
    (n,), pos = _take(buf, 0, "<u8")
    images = []
    for _ in range(int(n)):
        (rec,), pos = _take(buf, pos, np.dtype([("id", "<u4"), ("q", "<f8", 4), ("t", "<f8", 3),
                                                ("cam", "<u4")]))
        end = buf.index(b"\0", pos)
        name, pos = buf[pos:end].decode(), end + 1
        (n2d,), pos = _take(buf, pos, "<u8")
        xys, pos = _take(buf, pos, np.dtype([("x", "<f8"), ("y", "<f8"), ("p", "<u8")]), int(n2d))
        images.append((int(rec["id"]), tuple(rec["q"].tolist()), tuple(rec["t"].tolist()),
                       int(rec["cam"]), name, [tuple(r) for r in xys.tolist()]))
    buf = open(os.path.join(folder, "points3D.bin"), "rb").read()
    (n,), pos = _take(buf, 0, "<u8")
    points = []
    for _ in range(int(n)):
        (rec,), pos = _take(buf, pos, np.dtype([("id", "<u8"), ("xyz", "<f8", 3),
                                                ("rgb", "u1", 3), ("err", "<f8"), ("n", "<u8")]))
        track, pos = _take(buf, pos, np.dtype([("i", "<u4"), ("k", "<u4")]), int(rec["n"]))
        points.append((int(rec["id"]), tuple(rec["xyz"].tolist()), tuple(rec["rgb"].tolist()),
                       float(rec["err"]), [tuple(r) for r in track.tolist()]))
    return cameras, images, points


def write_bin(folder, cameras, images, points):
    os.makedirs(folder, exist_ok=True)
    with open(os.path.join(folder, "cameras.bin"), "wb") as f:
        f.write(struct.pack("<Q", len(cameras)))
        for cid, model, w, h, params in cameras:
            f.write(struct.pack(f"<IiQQ{len(params)}d", cid, model, w, h, *params))
    with open(os.path.join(folder, "images.bin"), "wb") as f:
        f.write(struct.pack("<Q", len(images)))
        for iid, q, t, cid, name, xys in images:
            f.write(struct.pack("<I7dI", iid, *q, *t, cid) + name.encode() + b"\0")
            f.write(struct.pack("<Q", len(xys)))
            for x, y, p in xys:
                f.write(struct.pack("<ddQ", x, y, p))
    with open(os.path.join(folder, "points3D.bin"), "wb") as f:
        f.write(struct.pack("<Q", len(points)))
        for pid, xyz, rgb, err, track in points:
            f.write(struct.pack("<Q3d3BdQ", pid, *xyz, *rgb, err, len(track)))
            for i, k in track:
                f.write(struct.pack("<II", i, k))


def write_txt(folder, cameras, images, points):
    os.makedirs(folder, exist_ok=True)
    r = lambda v: repr(float(v))  # shortest round-tripping float text
    with open(os.path.join(folder, "cameras.txt"), "w") as f:
        f.write("# Camera list with one line of data per camera:\n")
        for cid, model, w, h, params in cameras:
            fields = [str(cid), MODEL_NAMES[model], str(w), str(h)] + [r(p) for p in params]
            f.write(" ".join(fields) + "\n")
    with open(os.path.join(folder, "images.txt"), "w") as f:
        f.write("# Image list with two lines of data per image:\n#\n")
        for iid, q, t, cid, name, xys in images:
            f.write(" ".join([str(iid)] + [r(v) for v in (*q, *t)] + [str(cid), name]) + "\n")
            f.write(" ".join(f"{r(x)} {r(y)} {-1 if p == NO_POINT else p}" for x, y, p in xys)
                    + "\n")
    with open(os.path.join(folder, "points3D.txt"), "w") as f:
        f.write("# 3D point list with one line of data per point:\n")
        for pid, xyz, rgb, err, track in points:
            f.write(" ".join([str(pid)] + [r(v) for v in xyz] + [str(c) for c in rgb] + [r(err)]
                             + [f"{i} {k}" for i, k in track]) + "\n")
