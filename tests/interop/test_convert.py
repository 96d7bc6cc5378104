"""`transcode convert` against independent writers and readers of the four splat formats.

- gsply writes a 3DGS PLY; we convert it through every format and back to PLY, and plyfile checks
  each attribute against gsply's values within the quantisation of the formats passed through.
- @playcanvas/splat-transform (npm, when SPLAT_TRANSFORM_NODE_PATH names a node_modules folder
  holding it) writes a `.glb` with KHR_gaussian_splatting that we read, and reads the `.splat`
  we write. splat-transform 3.7 writes no `.splat`, so no independent `.splat` writer is tested.

Frames: our `.glb` holds the model turned half a turn about x (our right-down-forward frame to
glTF's y-up); splat-transform turns a PLY half a turn about z instead (PlayCanvas's convention).
Both give y up; they differ by a half turn about y (which side of the model faces +z), which is
applied here, written out independently, before comparing.
"""

import os
import subprocess
from pathlib import Path

import gsply
import numpy as np
import pytest
from plyfile import PlyData

REPO = Path(__file__).resolve().parents[2]
GT = REPO / "testdata" / "splat-scene" / "gt.ply"
TRANSCODE = os.environ.get("TRANSCODE_BIN", "")
# Inria's real SH basis, degree 1..3, as monomials in x, y, z (constants do not matter here).
BASIS = ["y", "z", "x", "xy", "yz", "zz", "xz", "xx", "yxx", "xyz", "yzz", "zzz", "xzz", "zxx", "xxx"]


def convert(*args):
    assert TRANSCODE and Path(TRANSCODE).is_file(), "set TRANSCODE_BIN to the transcode binary"
    run = subprocess.run([TRANSCODE, "convert", *map(str, args)], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    return run.stdout


def ply_arrays(path):
    """means, log-scales, unit wxyz quats, opacity logits, DC [N, 3], rest [N, K, 3]."""
    v = PlyData.read(str(path))["vertex"]
    names = v.data.dtype.names
    k = sum(n.startswith("f_rest_") for n in names) // 3
    quats = np.stack([v[f"rot_{i}"] for i in range(4)], 1).astype(np.float64)
    return (
        np.stack([v["x"], v["y"], v["z"]], 1),
        np.stack([v[f"scale_{i}"] for i in range(3)], 1),
        quats / np.linalg.norm(quats, axis=1, keepdims=True),
        np.asarray(v["opacity"]),
        np.stack([v[f"f_dc_{i}"] for i in range(3)], 1),
        np.stack([v[f"f_rest_{i}"] for i in range(3 * k)] or [np.zeros(len(quats))], 1)[:, : 3 * k]
        .reshape(len(quats), 3, k)
        .transpose(0, 2, 1),
    )


def rotation_angle(a, b):
    """Angle between two arrays of unit wxyz quaternions (q and -q are the same rotation)."""
    return 2 * np.arccos(np.clip(np.abs(np.sum(a * b, 1)), 0, 1))


def sig(x):
    return 1 / (1 + np.exp(-np.asarray(x, np.float64)))


def test_cli_reports_what_it_wrote_and_refuses_unknown_formats(tmp_path):
    out = convert(GT, tmp_path / "gt.splat")
    assert "warning: .splat keeps only the diffuse colour" in out
    assert "4000 splats, SH degree 0, 128000 bytes" in out
    out = convert(tmp_path / "gt.splat", tmp_path / "back.glb")
    assert "4000 splats, SH degree 0" in out and "warning" not in out
    run = subprocess.run([TRANSCODE, "convert", GT, tmp_path / "x.obj"], capture_output=True, text=True)
    assert run.returncode != 0 and "unknown splat format `.obj`" in run.stderr
    run = subprocess.run([TRANSCODE, "convert", GT, tmp_path / "x.glb", "--sh1-bits", "6"], capture_output=True, text=True)
    assert run.returncode != 0 and "apply to .spz output only" in run.stderr
    assert not (tmp_path / "x.glb").exists()


@pytest.mark.parametrize("middle", ["ply", "spz", "splat", "glb"])
def test_gsply_ply_through_each_format_and_back(tmp_path, middle):
    src = tmp_path / "gsply.ply"
    data = gsply.plyread(str(GT))
    gsply.plywrite(str(src), data)
    mid, back = tmp_path / f"mid.{middle}", tmp_path / "back.ply"
    convert(src, mid)
    convert(mid, back)
    means, scales, quats, opac, dc, rest = ply_arrays(src)
    bm, bs, bq, bo, bdc, brest = ply_arrays(back)
    if middle == "splat":
        # The writer sorts the records: pair the splats by their (exactly stored) positions.
        order = np.lexsort(means.T[::-1])
        border = np.lexsort(bm.T[::-1])
        means, scales, quats, opac, dc = (a[order] for a in (means, scales, quats, opac, dc))
        bm, bs, bq, bo, bdc = (a[border] for a in (bm, bs, bq, bo, bdc))
    if middle in ("ply", "glb", "splat"):
        np.testing.assert_array_equal(bm, means)
    else:  # SPZ: 24-bit fixed point
        assert np.abs(bm - means).max() < 2.0**-12
    tol = {"ply": 0, "glb": 1e-5, "splat": 1e-5, "spz": 1 / 32 + 1e-5}[middle]
    assert np.abs(bs - (np.clip(scales, -10, 255 / 16 - 10) if middle == "spz" else scales)).max() <= tol
    tol = {"ply": 1e-7, "glb": 1e-6, "splat": 0.5 / 255 + 1e-6, "spz": 0.5 / 255 + 1e-4}[middle]
    # glb and .splat store the activated opacity, read back through logit's clamp to (1e-6, 1 - 1e-6).
    want = np.clip(sig(opac), 1e-6, 1 - 1e-6) if middle in ("glb", "splat") else sig(opac)
    assert np.abs(sig(bo) - want).max() <= tol
    tol = {"ply": 1e-6, "glb": 1e-3, "splat": 0.04, "spz": 4e-3}[middle]
    assert rotation_angle(bq, quats).max() < tol
    if middle == "splat":
        rgb = np.clip(0.5 + gsply.SH_C0 * dc, 0, 1)
        assert np.abs(0.5 + gsply.SH_C0 * bdc - rgb).max() <= 0.5 / 255 + 1e-6
        assert brest.shape[1] == 0
    else:
        tol = {"ply": 0, "glb": 0, "spz": 0.5 / (0.15 * 255) + 1e-5}[middle]
        assert np.abs(bdc - dc).max() <= tol
        assert brest.shape == rest.shape
        if middle != "spz":
            np.testing.assert_array_equal(brest, rest)


def test_we_read_splat_transforms_glb(tmp_path, splat_transform):
    st = splat_transform
    glb, back = tmp_path / "st.glb", tmp_path / "back.ply"
    st(GT, glb)
    convert(glb, back)
    means, scales, quats, opac, dc, rest = ply_arrays(GT)
    bm, bs, bq, bo, bdc, brest = ply_arrays(back)
    # A half turn about y: (x, y, z) -> (-x, y, -z); rotation R -> Ry R; SH coefficient sign from
    # the parity of its x and z factors.
    np.testing.assert_allclose(bm, means * [-1, 1, -1], atol=1e-6)
    ry = np.diag([-1.0, 1.0, -1.0])

    def matrix(q):
        w, x, y, z = q.T
        return np.stack([
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ], -2)

    # Compared as covariances R S² Rᵀ: the frame change here conjugates R by diag(1, -1, -1), so
    # the splat's own axes may come back with their signs flipped, which an ellipsoid does not see.
    def cov(q, s):
        r = matrix(q)
        return r @ (np.exp(2 * s.astype(np.float64))[:, :, None] * r.transpose(0, 2, 1))

    want = ry @ cov(quats, scales) @ ry
    np.testing.assert_allclose(cov(bq, bs), want, rtol=1e-4, atol=1e-4 * np.abs(want).max())
    np.testing.assert_allclose(bs, scales, atol=1e-5)
    np.testing.assert_allclose(sig(bo), np.clip(sig(opac), 1e-6, 1 - 1e-6), atol=1e-6)
    np.testing.assert_allclose(bdc, dc, atol=1e-6)
    sign = np.array([(-1.0) ** (m.count("x") + m.count("z")) for m in BASIS])
    np.testing.assert_allclose(brest, rest * sign[None, :, None], atol=1e-6)


def test_splat_transform_reads_our_splat(tmp_path, splat_transform):
    st = splat_transform
    ours, theirs = tmp_path / "gt.splat", tmp_path / "st.ply"
    convert(GT, ours)
    st(ours, theirs)
    means, scales, quats, opac, dc, _ = ply_arrays(GT)
    tm, ts, tq, to, tdc, _ = ply_arrays(theirs)
    order, torder = np.lexsort(means.T[::-1]), np.lexsort(tm.T[::-1])
    means, scales, quats, opac, dc = (a[order] for a in (means, scales, quats, opac, dc))
    tm, ts, tq, to, tdc = (a[torder] for a in (tm, ts, tq, to, tdc))
    np.testing.assert_array_equal(tm, means)
    assert np.abs(ts - scales).max() <= 1e-5
    assert np.abs(sig(to) - sig(opac)).max() <= 0.5 / 255 + 1e-4
    assert np.abs(np.clip(0.5 + 0.28209479 * tdc, 0, 1) - np.clip(0.5 + 0.28209479 * dc, 0, 1)).max() <= 0.5 / 255 + 1e-4
    assert rotation_angle(tq, quats).max() < 0.04
