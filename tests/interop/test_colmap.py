"""Interoperability of colmap-io with the real COLMAP, through pycolmap.

Models written by colmap-io (via `transcode colmap convert`, text and binary) must load in
pycolmap with the same cameras, poses, points and tracks as the source, and models written by
pycolmap (every camera model, text and binary, with its rigs.bin/frames.bin) must read back
equal in colmap-io. Needs TRANSCODE_BIN (the debug `transcode` binary) (test data from `testdata/`).
"""

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pycolmap
import pytest

REPO = Path(__file__).resolve().parents[2]
TRANSCODE = os.environ.get("TRANSCODE_BIN", "")
TESTDATA = REPO / "testdata"
MAUPERTUIS = TESTDATA / "colmap" / "maupertuis" / "sparse" / "0"


def transcode(*args):
    """Runs the transcode binary and returns its standard output."""
    assert TRANSCODE and Path(TRANSCODE).is_file(), "set TRANSCODE_BIN to the transcode binary"
    done = subprocess.run([TRANSCODE, *map(str, args)], capture_output=True, text=True)
    assert done.returncode == 0, f"transcode {' '.join(map(str, args))} failed:\n{done.stderr}"
    return done.stdout


def cam_from_world(image):
    """The image's pose as a Rigid3d (a method in pycolmap >= 3.12, an attribute before)."""
    pose = image.cam_from_world
    return pose() if callable(pose) else pose


def model_name(camera):
    return camera.model.name if hasattr(camera.model, "name") else str(camera.model)


def assert_same(expected, actual):
    """Exact equality of cameras, poses, keypoints, points and tracks of two reconstructions."""
    assert sorted(expected.cameras) == sorted(actual.cameras)
    for cid, a in expected.cameras.items():
        b = actual.cameras[cid]
        assert model_name(a) == model_name(b), cid
        assert (a.width, a.height) == (b.width, b.height), cid
        assert np.array_equal(a.params, b.params), (cid, a.params, b.params)
    assert sorted(expected.images) == sorted(actual.images)
    for iid, a in expected.images.items():
        b = actual.images[iid]
        assert (a.name, a.camera_id) == (b.name, b.camera_id), iid
        pa, pb = cam_from_world(a), cam_from_world(b)
        assert np.array_equal(pa.rotation.quat, pb.rotation.quat), (iid, pa.rotation.quat, pb.rotation.quat)
        assert np.array_equal(pa.translation, pb.translation), iid
        assert len(a.points2D) == len(b.points2D), iid
        xa = np.array([p.xy for p in a.points2D]).reshape(-1, 2)
        xb = np.array([p.xy for p in b.points2D]).reshape(-1, 2)
        assert np.array_equal(xa, xb), iid
        assert [p.point3D_id for p in a.points2D] == [p.point3D_id for p in b.points2D], iid
    assert sorted(expected.points3D) == sorted(actual.points3D)
    for pid, a in expected.points3D.items():
        b = actual.points3D[pid]
        assert np.array_equal(a.xyz, b.xyz), pid
        assert np.array_equal(a.color, b.color), pid
        assert a.error == b.error, pid
        ta = sorted((e.image_id, e.point2D_idx) for e in a.track.elements)
        tb = sorted((e.image_id, e.point2D_idx) for e in b.track.elements)
        assert ta == tb, pid


@pytest.mark.parametrize("encoding", ["txt", "bin"])
def test_models_written_by_colmap_io_load_equal_in_pycolmap(tmp_path, encoding):
    source = pycolmap.Reconstruction(str(MAUPERTUIS))
    assert (source.num_cameras(), source.num_images(), source.num_points3D()) == (1, 4, 1039)
    out = tmp_path / encoding
    transcode("colmap", "convert", MAUPERTUIS, out, "--to", encoding)
    assert sorted(p.name for p in out.iterdir()) == sorted(
        f"{n}.{encoding}" for n in ("cameras", "images", "points3D")
    )
    ours = pycolmap.Reconstruction(str(out))
    assert_same(source, ours)
    assert ours.compute_num_observations() == 3355
    # A second generation (binary → text or text → binary) is still identical.
    other = "bin" if encoding == "txt" else "txt"
    transcode("colmap", "convert", out, tmp_path / "again", "--to", other)
    assert_same(source, pycolmap.Reconstruction(str(tmp_path / "again")))


def camera_models():
    return [m for name, m in pycolmap.CameraModelId.__members__.items() if name != "INVALID"]


def pycolmap_model(rng):
    """A reconstruction built in pycolmap: one camera of every model, one image each with a
    random pose and keypoints, and 3D points observed by several images."""
    rec = pycolmap.Reconstruction()
    for cid, model in enumerate(camera_models(), start=1):
        camera = pycolmap.Camera.create_from_model_id(cid, model, 500.0, 640 + cid, 480)
        camera.params = rng.uniform(0.1, 900.0, size=len(camera.params))
        rec.add_camera_with_trivial_rig(camera)
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        pose = pycolmap.Rigid3d(pycolmap.Rotation3d(q), rng.normal(size=3) * 10)
        keypoints = rng.uniform(0, 480, size=(6, 2))
        image = pycolmap.Image(name=f"view_{cid:02d}.png", keypoints=keypoints, camera_id=cid, image_id=100 + cid)
        rec.add_image_with_trivial_frame(image, pose)
    image_ids = sorted(rec.images)
    for k in range(5):
        track = pycolmap.Track()
        for iid in image_ids[k : k + 3]:
            track.add_element(iid, k)
        rec.add_point3D(rng.normal(size=3) * 5, track, rng.integers(0, 256, size=3).astype(np.uint8))
    return rec


@pytest.mark.parametrize("encoding", ["txt", "bin"])
def test_models_written_by_pycolmap_read_back_equal_in_colmap_io(tmp_path, encoding):
    rng = np.random.default_rng(42)
    built = pycolmap_model(rng)
    written = tmp_path / "pycolmap"
    written.mkdir()
    if encoding == "txt":
        built.write_text(str(written))
    else:
        built.write_binary(str(written))
    reference = pycolmap.Reconstruction(str(written))

    # colmap-io reads it (ignoring rigs/frames files) and reports the same cameras.
    info = json.loads(transcode("colmap", "info", written, "--json"))
    assert info["format"] == ("text" if encoding == "txt" else "binary")
    assert (info["cameras"], info["images"], info["points3d"]) == (len(camera_models()), len(camera_models()), 5)
    assert info["observations"] == reference.compute_num_observations()
    # pycolmap >= 3.12 writes rigs and frames beside the classic files; colmap-io reads without them.
    newer = sorted(p.name for p in written.iterdir() if p.stem in ("rigs", "frames"))
    assert sorted(info["ignored_files"]) == newer
    for cam in info["camera_list"]:
        ref = reference.cameras[cam["id"]]
        assert cam["model"] == model_name(ref)
        assert (cam["width"], cam["height"]) == (ref.width, ref.height)
        assert cam["params"] == list(ref.params)
        assert ", ".join(cam["param_names"]).replace(" ", "") == ref.params_info.replace(" ", "")

    # What colmap-io writes back, in either encoding, is what pycolmap wrote.
    for target in ("txt", "bin"):
        out = tmp_path / f"colmap_io_{target}"
        transcode("colmap", "convert", written, out, "--to", target)
        assert_same(reference, pycolmap.Reconstruction(str(out)))


@pytest.mark.parametrize("encoding", ["txt", "bin"])
def test_rig_cameras_project_like_colmap(tmp_path, encoding):
    """A transcoder-style rig (Fibonacci cameras, one at the pole, one from a PccAppRenderer
    viewport) written by colmap-io: COLMAP's own projection of every point lands on the pixel
    that camera-model computed, so poses, quaternion order and pixel centres agree."""
    out = tmp_path / "rig"
    done = subprocess.run(
        ["cargo", "run", "--quiet", "-p", "colmap-io", "--example", "rig_model", "--", str(out), encoding],
        cwd=REPO,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    rec = pycolmap.Reconstruction(str(out))
    assert (rec.num_cameras(), rec.num_images(), rec.num_points3D()) == (1, 13, 200)
    camera = rec.cameras[1]
    assert model_name(camera) == "PINHOLE"
    assert list(camera.params[2:]) == [400.0, 300.0]
    rows = [line.split() for line in (out / "projections.txt").read_text().splitlines() if not line.startswith("#")]
    assert len(rows) == 13 * 200
    worst = 0.0
    for image_id, point_id, u, v in rows:
        image = rec.images[int(image_id)]
        uv = image.project_point(rec.points3D[int(point_id)].xyz)
        assert uv is not None
        worst = max(worst, float(np.abs(np.asarray(uv).ravel() - [float(u), float(v)]).max()))
    assert worst < 1e-6, f"pycolmap and camera-model differ by {worst} px"
