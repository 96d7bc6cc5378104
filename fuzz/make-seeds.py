#!/usr/bin/env python3
"""Fills fuzz/seeds/<target>/ from testdata/ (run from anywhere; overwrites the seed folders).

Seeds are kept small (a few KB each): big test files are cut to their first records and their
declared counts rewritten to match, so the mutator spends its time on structure, not bulk.
"""
import pathlib
import gzip
import json
import re
import shutil
import struct

ROOT = pathlib.Path(__file__).resolve().parent.parent
TD = ROOT / "testdata"
SEEDS = ROOT / "fuzz" / "seeds"


def put(target, name, data):
    d = SEEDS / target
    d.mkdir(parents=True, exist_ok=True)
    (d / name).write_bytes(data)


def copy(target, rel):
    src = TD / rel
    put(target, src.name, src.read_bytes())


def cut_ply(data, keep_rows):
    """The header with the vertex count set to keep_rows, then the bytes of that many rows
    (binary: fixed stride from the header; ascii: lines)."""
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode()
    sizes = {"char": 1, "uchar": 1, "short": 2, "ushort": 2, "int": 4, "uint": 4,
             "float": 4, "double": 8}
    in_vertex, stride = False, 0
    for line in header.splitlines():
        w = line.split()
        if w[:1] == ["element"]:
            in_vertex = w[1] == "vertex"
        elif w[:1] == ["property"] and in_vertex:
            stride += sizes[w[1]]
    header = re.sub(r"element vertex \d+", f"element vertex {keep_rows}", header)
    body = data[end:]
    if "format ascii" in header:
        body = b"".join(body.splitlines(keepends=True)[:keep_rows])
    else:
        body = body[: keep_rows * stride]
    return header.encode() + body


def plenoptic_ply(fmt, cameras=2, points=3):
    """A tiny 8iVSLF-layout cloud: rig comments, float xyz + normals, uchar colours per camera."""
    lines = ["ply", f"format {fmt} 1.0",
             "comment frame_to_world_scale 0.0018", "comment frame_to_world_translation 1 2 3",
             "comment width 1023", f"comment rig_count {cameras}"]
    for k in range(cameras):
        lines.append(f"comment rig_matrix_{k} 1 0 0 0 0 1 0 0 0 0 1 0 {k} 2 -3 1")
    lines.append(f"element vertex {points}")
    props = [("float", n) for n in ("x", "y", "z", "nx", "ny", "nz")]
    for k in range(cameras):
        props += [("uchar", f"{c}{k}") for c in ("red", "green", "blue")]
    lines += [f"property {t} {n}" for t, n in props]
    lines.append("end_header")
    head = ("\n".join(lines) + "\n").encode()
    rows = []
    for i in range(points):
        vals = [float(i), 2.0 * i, 3.0, 0.0, 0.0, 1.0] + [(40 * i + j) % 256 for j in range(3 * cameras)]
        rows.append(vals)
    if fmt == "ascii":
        return head + "".join(" ".join(str(v) for v in r) + "\n" for r in rows).encode()
    e = "<" if fmt == "binary_little_endian" else ">"
    body = b"".join(struct.pack(e + "6f" + f"{3 * cameras}B", *r) for r in rows)
    return head + body


def main():
    if SEEDS.exists():
        shutil.rmtree(SEEDS)
    # plenoptic-io PLY: clouds and meshes.
    for rel in ["meshes/misc/cube_binary.ply", "meshes/misc/cube_uv.ply",
                "meshes/misc/float-color.ply", "meshes/misc/points.ply", "bad/issue623.ply"]:
        copy("plenoptic_ply", rel)
    put("plenoptic_ply", "pond-cut.ply", cut_ply((TD / "bad/pond.0.ply").read_bytes(), 8))
    for fmt in ("ascii", "binary_little_endian", "binary_big_endian"):
        put("plenoptic_ply", f"8i-{fmt}.ply", plenoptic_ply(fmt))
    # OBJ.
    for rel in ["meshes/misc/cube_with_vertexcolors.obj", "bad/malformed.obj", "bad/malformed2.obj"]:
        copy("mesh_obj", rel)
    put("mesh_obj", "with-mtl.obj",
        b"mtllib fuzz.mtl\no a\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvt 0 0\nvt 1 0\nvt 0 1\n"
        b"vn 0 0 1\nusemtl a\nf 1/1/1 2/2/1 3/3/1\nf 2/2/1 4/1/1 3/3/1\n")
    # glTF / GLB (the target puts BoxTextured0.bin, CesiumLogoFlat.png, IndexOutOfRange.bin beside).
    for rel in ["meshes/box-textured/BoxTextured.glb", "meshes/box-textured/BoxTextured.gltf",
                "bad/gltf/IndexOutOfRange/IndexOutOfRange.gltf",
                "bad/gltf/BoxWithInfinites-glTF-Binary/BoxWithInfinites.glb"]:
        copy("mesh_gltf", rel)
    # COLMAP text: first byte 0/1/2 = cameras/images/points3D; the big files cut to a few records.
    sparse = TD / "colmap/maupertuis/sparse/0"
    cams = (sparse / "cameras.txt").read_bytes()
    put("colmap_text", "cameras.txt", b"\x00" + cams)
    put("colmap_text", "cameras-models.txt", b"\x00" + b"1 PINHOLE 640 480 500 500 320 240\n"
        b"2 OPENCV 640 480 500 500 320 240 0.1 -0.01 0.001 0.002\n3 SIMPLE_RADIAL 10 10 5 5 5 0\n")
    images = (sparse / "images.txt").read_text().splitlines(keepends=True)
    img = images[:4] + [images[4], " ".join(images[5].split()[:30]) + "\n"]
    put("colmap_text", "images.txt", b"\x01" + "".join(img).encode())
    put("colmap_text", "images-observed.txt", b"\x01" + b"1 1 0 0 0 0 0 0 1 a.jpg\n1 2 -1 3 4 7\n")
    points = (sparse / "points3D.txt").read_text().splitlines(keepends=True)
    put("colmap_text", "points3D.txt", b"\x02" + "".join(points[:10]).encode())
    # COLMAP binary: the same records in the binary layout.
    put("colmap_binary", "cameras.bin", b"\x00" + struct.pack("<QIiQQ3d", 1, 1, 0, 1919, 1079, 1847.53, 959.5, 539.5))
    put("colmap_binary", "cameras-opencv.bin", b"\x00" + struct.pack("<QIiQQ8d", 1, 7, 4, 640, 480, 500, 500, 320, 240, 0.1, -0.01, 0.001, 0.002))
    im = struct.pack("<QI7dI", 1, 1, 1, 0, 0, 0, 1, 2, 3, 1) + b"00.jpg\x00" + struct.pack("<Q", 2)
    im += struct.pack("<2dQ", 1.5, 2.5, 2**64 - 1) + struct.pack("<2dQ", 3.5, 4.5, 7)
    put("colmap_binary", "images.bin", b"\x01" + im)
    pt = struct.pack("<QQ3d3Bd", 1, 7, 1.0, 2.0, 3.0, 10, 20, 30, 0.5) + struct.pack("<Q2I", 1, 1, 1)
    put("colmap_binary", "points3D.bin", b"\x02" + pt)
    # 3DGS PLY: the scene's splats cut to a few records, with and without SH rest.
    gt = (TD / "splat-scene/gt.ply").read_bytes()
    put("splat_ply", "gt-cut.ply", cut_ply(gt, 4))
    head = (b"ply\nformat ascii 1.0\nelement vertex 2\n" + b"".join(
        b"property float " + n.encode() + b"\n" for n in
        ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
         "rot_0", "rot_1", "rot_2", "rot_3"]) + b"end_header\n")
    put("splat_ply", "sh0-ascii.ply", head + b"0 0 0 0.1 0.2 0.3 0 -3 -3 -3 1 0 0 0\n"
        b"1 1 1 -0.1 0 0.5 2 -2 -4 -1 0.7 0.7 0 0\n")
    # SPZ: a version-3 stream of two degree-1 splats, as content (mode byte 0: the target
    # compresses it) and as a gzip file (mode byte 1), plus a version-2 one.
    n = 2
    payload = struct.pack("<IIIBBBB", 0x5053474E, 3, n, 1, 12, 0, 0)
    payload += bytes([0, 16, 0, 0, 240, 255, 128, 0, 0]) + bytes([1, 2, 3, 4, 5, 6, 7, 8, 9])
    payload += bytes([200, 100])  # alphas
    payload += bytes([127, 140, 100, 50, 60, 70])  # colours
    payload += bytes([96, 96, 80, 120, 100, 90])  # log-scales
    payload += struct.pack("<II", 3 << 30, (1 << 30) | 0x12345)  # smallest-three rotations
    payload += bytes(range(120, 129)) + bytes(range(64, 73))  # degree-1 SH
    put("splat_spz", "v3-content.bin", b"\x00" + payload)
    put("splat_spz", "v3.spz", b"\x01" + gzip.compress(payload, mtime=0))
    v2 = bytearray(payload[: 16 + 9 * n + n + 3 * n + 3 * n])
    v2[4] = 2
    v2 += bytes([127, 127, 127, 200, 90, 30]) + payload[16 + 9 * n + 7 * n + 4 * n:]
    put("splat_spz", "v2-content.bin", b"\x00" + bytes(v2))
    # Version 4: the same blocks, each in a zstd frame of one raw block (single segment, its
    # 1-byte content size, no checksum), behind a clear 32-byte header and the table.
    blocks, at = [], 16
    for size in (9 * n, n, 3 * n, 3 * n, 4 * n, 9 * n):
        blocks.append(payload[at:at + size])
        at += size
    frames = [struct.pack("<IBB", 0xFD2FB528, 0x20, len(b)) + ((len(b) << 3) | 1).to_bytes(3, "little") + b
              for b in blocks]
    v4 = struct.pack("<IIIBBBBI", 0x5053474E, 4, n, 1, 12, 0, len(frames), 32) + bytes(12)
    v4 += b"".join(struct.pack("<QQ", len(f), len(b)) for f, b in zip(frames, blocks)) + b"".join(frames)
    put("splat_spz", "v4.spz", b"\x01" + v4)
    # .splat: two 32-byte records (position, linear scale, RGBA, quaternion bytes w x y z).
    put("splat_dotsplat", "two.splat",
        struct.pack("<6f4B4B", 0, 0, 0, 0.1, 0.2, 0.3, 255, 128, 0, 200, 255, 128, 128, 128)
        + struct.pack("<6f4B4B", 1, -2, 3, 1, 1, 0.01, 10, 20, 30, 40, 128, 218, 128, 38))
    # .glb: two degree-1 splats with KHR_gaussian_splatting, the layout glb::encode_glb writes.
    put("splat_glb", "two-sh1.glb", splat_glb(2, 1))
    put("splat_glb", "one-sh0.glb", splat_glb(1, 0))


def splat_glb(n, degree):
    """A .glb holding n splats of SH degree `degree` as KHR_gaussian_splatting float accessors."""
    ext = "KHR_gaussian_splatting"
    attrs = [("POSITION", "VEC3", 3), (ext + ":SCALE", "VEC3", 3),
             (ext + ":ROTATION", "VEC4", 4), (ext + ":OPACITY", "SCALAR", 1)]
    attrs += [(f"{ext}:SH_DEGREE_{d}_COEF_{c}", "VEC3", 3)
              for d in range(degree + 1) for c in range(2 * d + 1)]
    bin_, views, accessors, names = b"", [], [], {}
    for k, (name, kind, width) in enumerate(attrs):
        values = [0.5 + 0.25 * ((i * width + c) % 3) for i in range(n) for c in range(width)]
        data = struct.pack(f"<{len(values)}f", *values)
        views.append({"buffer": 0, "byteOffset": len(bin_), "byteLength": len(data)})
        accessors.append({"bufferView": k, "componentType": 5126, "count": n, "type": kind})
        names[name] = k
        bin_ += data
    accessors[0]["min"], accessors[0]["max"] = [0.5] * 3, [1.0] * 3
    doc = {"asset": {"version": "2.0"}, "extensionsUsed": [ext], "scene": 0,
           "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
           "meshes": [{"primitives": [{"attributes": names, "mode": 0,
                                       "extensions": {ext: {"kernel": "ellipse"}}}]}],
           "buffers": [{"byteLength": len(bin_)}], "bufferViews": views, "accessors": accessors}
    text = json.dumps(doc, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    total = 12 + 8 + len(text) + 8 + len(bin_)
    return (struct.pack("<III", 0x46546C67, 2, total) + struct.pack("<II", len(text), 0x4E4F534A)
            + text + struct.pack("<II", len(bin_), 0x004E4942) + bin_)


if __name__ == "__main__":
    main()
