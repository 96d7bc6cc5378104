"""Our .glb with KHR_gaussian_splatting (splat_core::glb) against the Khronos glTF validator and an
independent reading of the container here.

The validator (npm `gltf-validator`) predates KHR_gaussian_splatting: it reports the extension as
unsupported (info) and each `KHR_gaussian_splatting:*` attribute name as invalid, since core
glTF 2.0 only allows its own semantics and `_`-prefixed ones. The extension defines those names,
so these are the only findings allowed; anything else (buffers, alignment, accessor bounds and
types, the container) must be clean.
"""

import json
import os
import shutil
import struct
import subprocess
from pathlib import Path

import numpy as np
from plyfile import PlyData

REPO = Path(__file__).resolve().parents[2]
GT = REPO / "testdata" / "splat-scene" / "gt.ply"
EXT = "KHR_gaussian_splatting"


TRANSCODE = os.environ.get("TRANSCODE_BIN", "")


def convert(src, out):
    assert TRANSCODE and Path(TRANSCODE).is_file(), "set TRANSCODE_BIN to the transcode binary"
    subprocess.run([TRANSCODE, "convert", str(src), str(out)], check=True, capture_output=True)


def validate(path):
    node_path = os.environ.get("GLTF_VALIDATOR_NODE_PATH")
    assert node_path, "set GLTF_VALIDATOR_NODE_PATH to a node_modules folder holding gltf-validator"
    node = shutil.which("node")
    assert node, "node is needed to run the glTF validator"
    run = subprocess.run(
        [node, str(REPO / "tests" / "interop" / "js" / "validate_gltf.js"), str(path)],
        env={**os.environ, "NODE_PATH": node_path},
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(run.stdout)


def test_validator_finds_nothing_but_the_extensions_own_names(tmp_path):
    out = tmp_path / "gt.glb"
    convert(GT, out)
    issues = validate(out)
    unexpected = [
        m
        for m in issues["messages"]
        if not (
            (m["code"] == "UNSUPPORTED_EXTENSION" and EXT in m["message"])
            or (
                m["code"] == "MESH_PRIMITIVE_INVALID_ATTRIBUTE"
                and m["pointer"].startswith(f"/meshes/0/primitives/0/attributes/{EXT}:")
            )
        )
    ]
    assert unexpected == [], unexpected
    # Scale, rotation, opacity and the 16 SH coefficients of degree 3.
    named = [m for m in issues["messages"] if m["code"] == "MESH_PRIMITIVE_INVALID_ATTRIBUTE"]
    assert len(named) == 3 + 16


def test_positions_and_opacities_read_here_match_the_ply(tmp_path):
    out = tmp_path / "gt.glb"
    convert(GT, out)
    data = out.read_bytes()
    magic, version, length = struct.unpack_from("<III", data, 0)
    assert (magic, version, length) == (0x46546C67, 2, len(data))
    json_len, json_type = struct.unpack_from("<II", data, 12)
    assert json_type == 0x4E4F534A
    doc = json.loads(data[20 : 20 + json_len])
    bin_off = 20 + json_len
    bin_len, bin_type = struct.unpack_from("<II", data, bin_off)
    assert bin_type == 0x004E4942
    binary = data[bin_off + 8 : bin_off + 8 + bin_len]
    attrs = doc["meshes"][0]["primitives"][0]["attributes"]

    def read(semantic, width):
        acc = doc["accessors"][attrs[semantic]]
        view = doc["bufferViews"][acc["bufferView"]]
        assert acc["componentType"] == 5126
        start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
        return np.frombuffer(binary, np.float32, acc["count"] * width, start).reshape(acc["count"], width)

    v = PlyData.read(str(GT))["vertex"]
    # glTF is y-up with +z towards the viewer: (x, -y, -z) of our right-down-forward frame.
    np.testing.assert_array_equal(read("POSITION", 3), np.stack([v["x"], -v["y"], -v["z"]], 1))
    opacity = read(f"{EXT}:OPACITY", 1)[:, 0]
    np.testing.assert_allclose(opacity, 1 / (1 + np.exp(-v["opacity"].astype(np.float64))), rtol=1e-6)
    # The extension's SCALE is linear: the exponential of the PLY's log-scales.
    scale = read(f"{EXT}:SCALE", 3)
    log_scales = np.stack([v[f"scale_{i}"] for i in range(3)], 1).astype(np.float64)
    np.testing.assert_allclose(scale, np.exp(log_scales), rtol=1e-6)
    rot = read(f"{EXT}:ROTATION", 4)
    np.testing.assert_allclose(np.linalg.norm(rot, axis=1), 1, atol=1e-6)
