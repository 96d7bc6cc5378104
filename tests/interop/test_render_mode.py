"""How a model is drawn, as its file says: the antialiased (Mip-Splatting) render mode.

A model trained with the antialiased opacity compensation must be drawn with it. Brush writes
`comment SplatRenderMode: mip` into its PLY headers and Postshot `comment antialiased 1`;
PlayCanvas (SuperSplat) and @playcanvas/splat-transform read both, write Brush's spelling, and
carry the mode into SPZ's header flag (bit 0 of byte 14 of the decompressed stream) and back.
Here plyfile writes the tagged files independently of us, and these tests check that our
reader, our viewer's reader and `transcode render` / `eval` follow them, that `transcode
convert` carries the mode where the format has a place for it, and (with
SPLAT_TRANSFORM_NODE_PATH) that splat-transform and we agree on it in both directions.
"""

import gzip
import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from plyfile import PlyData

REPO = Path(__file__).resolve().parents[2]
GT = REPO / "testdata" / "splat-scene" / "gt.ply"
HELDOUT = REPO / "testdata" / "splat-scene" / "heldout"
FORMATS_JS = REPO / "splat-viewer" / "assets" / "js" / "formats.js"
TRANSCODE = os.environ.get("TRANSCODE_BIN", "")


def transcode(*args):
    assert TRANSCODE and Path(TRANSCODE).is_file(), "set TRANSCODE_BIN to the transcode binary"
    run = subprocess.run([TRANSCODE, *map(str, args)], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    return run.stdout


def tagged(path, comments):
    """gt.ply rewritten by plyfile with `comments` in its header."""
    ply = PlyData.read(str(GT))
    PlyData([ply["vertex"]], text=False, byte_order="<", comments=comments).write(str(path))
    return path


def spz_flag(path):
    """Bit 0 of the SPZ header's flags byte: version 4 keeps the header uncompressed, versions 2
    and 3 at the start of the gzip stream."""
    data = path.read_bytes()
    header = data if data[:4] == b"NGSP" else gzip.decompress(data)
    return header[14] & 1


def viewer_reads(path):
    node = shutil.which("node")
    assert node, "node is needed for the viewer's reader"
    run = subprocess.run(
        [node, str(REPO / "tests" / "interop" / "js" / "viewer_model.mjs"), str(FORMATS_JS), str(path)],
        capture_output=True, text=True, check=True,
    )
    return json.loads(run.stdout)


def ours_say_antialiased(path):
    """Whether our reader takes the file as antialiased: converted to SPZ, its flag."""
    out = path.with_name(path.stem + ".ours.spz")
    transcode("convert", path, out)
    return spz_flag(out) == 1


@pytest.mark.parametrize(
    "comments,want",
    [
        ([], False),
        (["Exported from Brush", "SH degree: 3", "SplatRenderMode: mip"], True),
        (["SplatRenderMode: default"], False),
        (["antialiased 1"], True),
        (["postshot.anti_aliasing=1"], True),
        (["antialiased 1", "SplatRenderMode: default"], False),
    ],
)
def test_our_reader_and_the_viewer_s_follow_the_header(tmp_path, comments, want):
    src = tagged(tmp_path / "m.ply", comments)
    assert ours_say_antialiased(src) == want
    seen = viewer_reads(src)
    assert seen["antialiased"] == want and seen["count"] == 4000 and seen["shDegree"] == 3


def test_convert_carries_the_mode_where_the_format_has_a_place_for_it(tmp_path):
    src = tagged(tmp_path / "brush.ply", ["SplatRenderMode: mip"])
    ply, spz, glb = tmp_path / "back.ply", tmp_path / "m.spz", tmp_path / "m.glb"
    transcode("convert", src, spz)
    assert spz_flag(spz) == 1
    assert viewer_reads(spz)["antialiased"]
    transcode("convert", spz, ply)
    # plyfile sees exactly Brush's comment in our header.
    assert PlyData.read(str(ply)).comments == ["SplatRenderMode: mip"]
    assert viewer_reads(ply)["antialiased"]
    out = transcode("convert", ply, glb)
    assert "trained antialiased" in out and "has no place for that" in out
    # An untagged model says nothing, in either format.
    plain_ply, plain_spz = tmp_path / "plain.ply", tmp_path / "plain.spz"
    transcode("convert", GT, plain_spz)
    transcode("convert", plain_spz, plain_ply)
    assert spz_flag(plain_spz) == 0 and PlyData.read(str(plain_ply)).comments == []


def png(path):
    return np.asarray(Image.open(path), dtype=np.int64)


def test_render_and_eval_draw_the_model_as_its_file_says(tmp_path):
    src = tagged(tmp_path / "aa.ply", ["SplatRenderMode: mip"])
    image = sorted(p.name for p in (HELDOUT / "images").iterdir())[0]
    shots = {}
    for label, extra in [("file", []), ("plain", ["--plain"]), ("aa", ["--antialiased"]),
                         ("untagged", None)]:
        model = GT if extra is None else src
        out = tmp_path / label
        transcode("render", model, "--colmap", HELDOUT, "--out", out, "--images", image, *(extra or []))
        shots[label] = png(out / (Path(image).stem + ".png"))
    assert np.array_equal(shots["file"], shots["aa"])
    assert np.array_equal(shots["plain"], shots["untagged"])
    # The compensation lowers small splats' opacity: the images differ, and the plain drawing
    # is the brighter on black.
    assert np.abs(shots["file"] - shots["plain"]).max() > 0
    assert shots["plain"].sum() > shots["file"].sum()
    said = transcode("eval", src, "--reference", HELDOUT)
    assert "drawn antialiased" in said
    assert "drawn plain" in transcode("eval", src, "--reference", HELDOUT, "--plain")
    run = subprocess.run([TRANSCODE, "render", src, "--colmap", HELDOUT, "--out", tmp_path / "x",
                          "--plain", "--antialiased"], capture_output=True, text=True)
    assert run.returncode != 0 and "cannot be used with" in run.stderr


def test_splat_transform_and_we_agree_on_the_mode_both_ways(tmp_path, splat_transform):
    st = splat_transform
    # Ours to theirs: our tagged PLY and SPZ, read by splat-transform and written as SPZ / PLY.
    src = tagged(tmp_path / "brush.ply", ["SplatRenderMode: mip"])
    ours_ply, ours_spz = tmp_path / "ours.ply", tmp_path / "ours.spz"
    transcode("convert", src, ours_spz)
    transcode("convert", ours_spz, ours_ply)
    for version in ("3", "4"):
        theirs = tmp_path / f"theirs_from_ply.v{version}.spz"
        st(ours_ply, theirs, "--spz-version", version)
        assert spz_flag(theirs) == 1
    # Their SPZ read by us, either version; and ours of either version read by them.
    for version in ("3", "4"):
        assert ours_say_antialiased(tmp_path / f"theirs_from_ply.v{version}.spz")
        ours_v = tmp_path / f"ours.v{version}.spz"
        transcode("convert", src, ours_v, "--spz-version", version)
        st(ours_v, tmp_path / f"theirs_from_ours.v{version}.ply")
        assert "SplatRenderMode: mip" in PlyData.read(str(tmp_path / f"theirs_from_ours.v{version}.ply")).comments
    st(ours_spz, tmp_path / "theirs_from_spz.ply")
    assert "SplatRenderMode: mip" in PlyData.read(str(tmp_path / "theirs_from_spz.ply")).comments
    # Theirs to ours: a Postshot-tagged PLY retagged by splat-transform in Brush's spelling.
    postshot = tagged(tmp_path / "postshot.ply", ["antialiased 1"])
    st(postshot, tmp_path / "retagged.ply")
    assert ours_say_antialiased(tmp_path / "retagged.ply")
    # And an untagged model stays untagged through them.
    st(GT, tmp_path / "plain.spz")
    assert spz_flag(tmp_path / "plain.spz") == 0
    assert not ours_say_antialiased(tmp_path / "plain.spz")
