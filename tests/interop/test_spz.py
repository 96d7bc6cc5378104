"""Our SPZ reader and writer (splat_core::spz) against gsply, an independent SPZ implementation.

gsply reads and writes SPZ's stored values as they are, with no change of frame. SPZ stores
right-up-back axes and our splats are in COLMAP's right-down-forward frame, so our writer turns
the model a half turn about x and our reader turns it back. These tests apply that turn here,
written out independently: position (x, -y, -z), quaternion (w, x, -y, -z), and each SH
coefficient's sign from the parity of the y and z factors of its basis polynomial.
"""

import os
import subprocess
from pathlib import Path

import gsply
import numpy as np
import pytest
from plyfile import PlyData

REPO = Path(__file__).resolve().parents[2]
TESTDATA = REPO / "testdata"
GT = TESTDATA / "splat-scene" / "gt.ply"

# Inria's real SH basis, degree 1..3, as monomials in x, y, z (constants do not matter here).
BASIS = ["y", "z", "x", "xy", "yz", "zz", "xz", "xx", "yxx", "xyz", "yzz", "zzz", "xzz", "zxx", "xxx"]
SH_SIGN = np.array([(-1.0) ** (m.count("y") + m.count("z")) for m in BASIS], dtype=np.float32)


TRANSCODE = os.environ.get("TRANSCODE_BIN", "")


def convert(*args):
    assert TRANSCODE and Path(TRANSCODE).is_file(), "set TRANSCODE_BIN to the transcode binary"
    subprocess.run([TRANSCODE, "convert", *map(str, args)], check=True, capture_output=True)


def gt_arrays():
    """The ground-truth model as plain arrays (plyfile): means, log-scales, unit wxyz quats,
    opacity logits, DC [N, 3] and rest [N, 15, 3]."""
    v = PlyData.read(str(GT))["vertex"]
    means = np.stack([v["x"], v["y"], v["z"]], 1)
    scales = np.stack([v[f"scale_{i}"] for i in range(3)], 1)
    quats = np.stack([v[f"rot_{i}"] for i in range(4)], 1)
    quats = quats / np.linalg.norm(quats, axis=1, keepdims=True)
    dc = np.stack([v[f"f_dc_{i}"] for i in range(3)], 1)
    rest = np.stack([v[f"f_rest_{i}"] for i in range(45)], 1).reshape(-1, 3, 15).transpose(0, 2, 1)
    return means, scales, quats, np.asarray(v["opacity"]), dc, rest


def half_turn_x(means, quats, rest):
    return (
        means * np.float32([1, -1, -1]),
        quats * np.float32([1, 1, -1, -1]),
        rest * SH_SIGN[None, :, None],
    )


def same_rotation(a, b):
    """Angle between two arrays of unit quaternions (q and -q are the same rotation)."""
    return 2 * np.arccos(np.clip(np.abs(np.sum(a * b, 1)), 0, 1))


def assert_ply_holds(ply, stored):
    """Our PLY `ply` (in our frame) holds what gsply read from an SPZ (`stored`, in SPZ's)."""
    v = PlyData.read(str(ply))["vertex"]
    means, quats, rest = half_turn_x(stored.means, stored.quats, stored.shN)
    np.testing.assert_allclose(np.stack([v["x"], v["y"], v["z"]], 1), means, atol=1e-6)
    np.testing.assert_allclose(np.stack([v[f"scale_{i}"] for i in range(3)], 1), stored.scales, atol=1e-6)
    np.testing.assert_allclose(v["opacity"], stored.opacities, atol=1e-4)
    ours = np.stack([v[f"rot_{i}"] for i in range(4)], 1)
    assert same_rotation(ours / np.linalg.norm(ours, axis=1, keepdims=True), quats).max() < 1e-3
    np.testing.assert_allclose(np.stack([v[f"f_dc_{i}"] for i in range(3)], 1), stored.sh0, atol=1e-6)
    ours_rest = np.stack([v[f"f_rest_{i}"] for i in range(45)], 1).reshape(-1, 3, 15).transpose(0, 2, 1)
    np.testing.assert_allclose(ours_rest, rest, atol=1e-6)


@pytest.mark.parametrize("version", [3, 4])
def test_gsply_reads_our_spz(tmp_path, version):
    out = tmp_path / "gt.spz"
    convert(GT, out, "--spz-version", version)
    # Version 4 keeps its header in the clear (gsply reads it with zstandard).
    assert (out.read_bytes()[:4] == b"NGSP") == (version == 4)
    got = gsply.read_spz(str(out))
    means, scales, quats, opac, dc, rest = gt_arrays()
    means, quats, rest = half_turn_x(means, quats, rest)
    assert got.means.shape == means.shape and got.shN.shape == rest.shape
    # Our writer keeps every coordinate within half a step of its fixed point.
    assert np.abs(got.means - means).max() < 2.0**-12
    assert np.abs(got.scales - np.clip(scales, -10, 255 / 16 - 10)).max() <= 1 / 32 + 1e-5
    sig = lambda x: 1 / (1 + np.exp(-x))
    assert np.abs(sig(got.opacities) - sig(opac)).max() <= 0.5 / 255 + 1e-4
    assert same_rotation(got.quats, quats).max() < 4e-3
    assert np.abs(got.sh0 - dc).max() <= 0.5 / (0.15 * 255) + 1e-5
    bucket = np.where(np.arange(15) < 3, 8 / 128, 16 / 128)[None, :, None]
    assert (np.abs(got.shN - np.clip(rest, -1, 127 / 128)) <= bucket / 2 + 1 / 256 + 1e-5).all()


@pytest.mark.parametrize("version", [3, 4])
def test_we_read_gsply_spz(tmp_path, version):
    src = tmp_path / "gsply.spz"
    gsply.write_spz(str(src), gsply.plyread(str(GT)), version=version, fractional_bits=12)
    stored = gsply.read_spz(str(src))
    out = tmp_path / "back.ply"
    convert(src, out)
    assert_ply_holds(out, stored)


@pytest.mark.parametrize("version", [3, 4])
def test_we_read_splat_transforms_spz(tmp_path, splat_transform, version):
    """splat-transform's SPZ (version 4 is its default) holds what gsply reads from it."""
    src, out = tmp_path / "st.spz", tmp_path / "back.ply"
    splat_transform(GT, src, "--spz-version", version)
    assert (src.read_bytes()[:4] == b"NGSP") == (version == 4)
    stored = gsply.read_spz(str(src))
    convert(src, out)
    assert_ply_holds(out, stored)


@pytest.mark.parametrize("version", [3, 4])
def test_splat_transform_reads_our_spz(tmp_path, splat_transform, version):
    """splat-transform turns our SPZ back into a PLY holding every splat within the format's
    quantisation. It keeps SPZ's right-up-back frame in the PLY (no turn), so the comparison is
    with the ground truth turned half a turn about x, as our writer stores it."""
    ours, theirs = tmp_path / "gt.spz", tmp_path / "st.ply"
    convert(GT, ours, "--spz-version", version)
    splat_transform(ours, theirs)
    v = PlyData.read(str(theirs))["vertex"]
    means, scales, quats, opac, dc, rest = gt_arrays()
    means, quats, rest = half_turn_x(means, quats, rest)
    assert v.count == len(means)
    assert np.abs(np.stack([v["x"], v["y"], v["z"]], 1) - means).max() < 2.0**-12
    got_scales = np.stack([v[f"scale_{i}"] for i in range(3)], 1)
    assert np.abs(got_scales - np.clip(scales, -10, 255 / 16 - 10)).max() <= 1 / 32 + 1e-5
    sig = lambda x: 1 / (1 + np.exp(-np.asarray(x, np.float64)))
    assert np.abs(sig(v["opacity"]) - sig(opac)).max() <= 0.5 / 255 + 1e-4
    q = np.stack([v[f"rot_{i}"] for i in range(4)], 1)
    assert same_rotation(q / np.linalg.norm(q, axis=1, keepdims=True), quats).max() < 4e-3
    assert np.abs(np.stack([v[f"f_dc_{i}"] for i in range(3)], 1) - dc).max() <= 0.5 / (0.15 * 255) + 1e-5
    got_rest = np.stack([v[f"f_rest_{i}"] for i in range(45)], 1).reshape(-1, 3, 15).transpose(0, 2, 1)
    bucket = np.where(np.arange(15) < 3, 8 / 128, 16 / 128)[None, :, None]
    assert (np.abs(got_rest - np.clip(rest, -1, 127 / 128)) <= bucket / 2 + 1 / 256 + 1e-5).all()
