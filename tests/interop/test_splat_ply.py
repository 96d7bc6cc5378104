"""Our 3DGS PLY writer against plyfile (the reader Inria's gaussian-splatting uses).

The files are written by `cargo run -p splat-core --example write_ply`; plyfile must read them
with Inria's published layout (formats.md §4.1): binary little endian, all `float`,
x y z nx ny nz f_dc_0..2 f_rest_* opacity scale_0..2 rot_0..3, f_rest channel-major.
"""

import subprocess
from pathlib import Path

import numpy as np
import pytest
from plyfile import PlyData

REPO = Path(__file__).resolve().parents[2]
TESTDATA = REPO / "testdata"


def inria_names(degree):
    k = (degree + 1) ** 2 - 1
    return (
        ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
        + [f"f_rest_{i}" for i in range(3 * k)]
        + ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    )


def write_ply(*args):
    subprocess.run(
        ["cargo", "run", "-q", "-p", "splat-core", "--example", "write_ply", "--", *map(str, args)],
        cwd=REPO,
        check=True,
    )


def check_layout(ply, degree, n):
    assert ply.text is False and ply.byte_order == "<"
    (vertex,) = ply.elements
    assert vertex.name == "vertex" and vertex.count == n
    assert [p.name for p in vertex.properties] == inria_names(degree)
    assert all(p.val_dtype in ("f4", "float32") for p in vertex.properties)
    return vertex


@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_synthetic_model_matches_the_published_layout(tmp_path, degree):
    out = tmp_path / f"synthetic_{degree}.ply"
    write_ply("synthetic", out, degree)
    v = check_layout(PlyData.read(str(out)), degree, 7)
    k = (degree + 1) ** 2 - 1
    for i in range(7):
        f = np.float32(i)
        np.testing.assert_array_equal([v["x"][i], v["y"][i], v["z"][i]], np.float32([0.5 * f, f, 1.5 * f]))
        assert v["nx"][i] == v["ny"][i] == v["nz"][i] == 0.0
        sh = lambda kk, c: np.float32(0.01) * np.float32(100 * i + 10 * kk + c)
        for c in range(3):
            assert v[f"f_dc_{c}"][i] == sh(0, c)
            for j in range(k):
                # channel-major: f_rest_{c*K' + j} is coefficient j + 1 of channel c
                assert v[f"f_rest_{c * k + j}"][i] == sh(j + 1, c)
        assert v["opacity"][i] == np.float32(i - 3)
        np.testing.assert_array_equal(
            [v["scale_0"][i], v["scale_1"][i], v["scale_2"][i]], np.float32([np.float32(-0.1) * f, -1.0, 0.25])
        )
        np.testing.assert_array_equal(
            [v["rot_0"][i], v["rot_1"][i], v["rot_2"][i], v["rot_3"][i]], np.float32([1.0, np.float32(0.1) * f, 0.0, -0.2])
        )


def test_copy_of_a_real_model_keeps_every_value(tmp_path):
    src = TESTDATA / "splat-scene" / "gt.ply"
    out = tmp_path / "copy.ply"
    write_ply("copy", src, out)
    original = PlyData.read(str(src))["vertex"]
    v = check_layout(PlyData.read(str(out)), 3, original.count)
    for name in inria_names(3):
        if name in ("nx", "ny", "nz"):
            assert not v[name].any()
            continue
        np.testing.assert_array_equal(v[name], original[name], err_msg=name)
