#!/usr/bin/env python3
"""The seed paper's experiment with the real COLMAP: splats initialised from the input's surface
against splats initialised from COLMAP's structure from motion on the rendered views.

One command (see docs/paper-experiment.md):

    python3 bench/paper_colmap.py --out /tmp/paper            # the experiment in BENCHMARKS.md
    python3 bench/paper_colmap.py --small --check --out DIR   # the version CI runs

Steps, each logged to OUT/logs/STEP.log:
 1. `transcode synth` makes a plenoptic frame from a real mesh (or `--frame` takes the user's);
 2. `transcode views` renders its training views as a COLMAP dataset;
 3. COLMAP: SIFT features on the CPU, exhaustive matching;
 4. COLMAP `point_triangulator` with our known poses held fixed (the paper's protocol), and
    `mapper`, a full SfM run without poses, aligned to our cameras afterwards (a least-squares
    similarity of the camera centres), reported beside it;
 5. `transcode run --points3d TRIANGULATED --compare-init`: the same views, the
    same held-out cameras, one model from COLMAP's points (Inria's densification) and one from
    the surface, each scored on the held-out views every `--eval-every` steps;
 6. OUT/paper.json and OUT/paper.md: the comparison, with the held-out pictures of both models.

Needs numpy, scipy and plyfile (bench/requirements.txt) and the `colmap` program (Debian's
`colmap` package, 3.8). Any failed step stops the experiment with the step's name and COLMAP's
own last lines; no comparison is ever written from a failed or thin SfM.
"""

from __future__ import annotations

import argparse
import filecmp
import json
import math
import os
import re
import shutil
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from plyfile import PlyData
from scipy.spatial import cKDTree

REPO = Path(__file__).resolve().parent.parent
SPIDER = REPO / "testdata" / "meshes" / "spider" / "spider.obj"


class StepFailed(Exception):
    """A step of the experiment failed: its name, and what the program printed."""


# --------------------------------------------------------------------------- running programs


def run(step: str, cmd: list[str], logs: Path) -> str:
    """Runs `cmd`, logging its output to logs/STEP.log; returns the output. Raises StepFailed
    with the step's name and the last lines the program printed when it fails."""
    logs.mkdir(parents=True, exist_ok=True)
    log = logs / f"{step}.log"
    print(f"== {step}: {' '.join(str(c) for c in cmd)}", flush=True)
    t = time.monotonic()
    try:
        p = subprocess.run(
            [str(c) for c in cmd], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
        )
    except FileNotFoundError as e:
        raise StepFailed(f"{step}: cannot start {cmd[0]} ({e})") from e
    log.write_text(p.stdout)
    if p.returncode != 0:
        tail = "\n".join(p.stdout.strip().splitlines()[-15:])
        raise StepFailed(
            f"{step} failed (exit status {p.returncode}); its last lines (whole log: {log}):\n{tail}"
        )
    print(f"   {time.monotonic() - t:.1f} s", flush=True)
    return p.stdout


# --------------------------------------------------------------------------- COLMAP text models


def read_cameras_txt(path: Path) -> dict[int, tuple[str, int, int, list[float]]]:
    cams = {}
    for line in path.read_text().splitlines():
        if not line.strip() or line.startswith("#"):
            continue
        f = line.split()
        cams[int(f[0])] = (f[1], int(f[2]), int(f[3]), [float(x) for x in f[4:]])
    return cams


def read_images_txt(path: Path) -> dict[str, dict]:
    """Images by name: id, qvec, tvec, camera id, and the number of 2-D points that see a 3-D
    point (observations)."""
    lines = [l for l in path.read_text().splitlines() if not l.startswith("#")]
    images = {}
    for head, pts in zip(lines[0::2], lines[1::2]):
        f = head.split()
        p = pts.split()
        ids = [int(x) for x in p[2::3]]
        images[f[9]] = {
            "id": int(f[0]),
            "q": [float(x) for x in f[1:5]],
            "t": [float(x) for x in f[5:8]],
            "camera": int(f[8]),
            "observations": sum(1 for i in ids if i != -1),
        }
    return images


def read_points3d_txt(path: Path) -> np.ndarray:
    rows = [
        [float(x) for x in l.split()[1:4]]
        for l in path.read_text().splitlines()
        if l.strip() and not l.startswith("#")
    ]
    return np.array(rows, dtype=np.float64).reshape(-1, 3)


def camera_centre(q: list[float], t: list[float]) -> np.ndarray:
    """World position of a COLMAP camera (world-to-camera rotation q, translation t): -Rᵀt."""
    w, x, y, z = q
    r = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )
    return -r.T @ np.array(t)


def umeyama(src: np.ndarray, dst: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """The similarity (scale s, rotation R, shift t) minimising sum |s R src_i + t - dst_i|²
    (Umeyama 1991, closed form from the SVD of the cross-covariance)."""
    mu_s, mu_d = src.mean(axis=0), dst.mean(axis=0)
    a, b = src - mu_s, dst - mu_d
    u, sig, vt = np.linalg.svd(b.T @ a / len(src))
    d = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        d[2, 2] = -1.0
    rot = u @ d @ vt
    scale = float(np.trace(np.diag(sig) @ d) / (a ** 2).sum(axis=1).mean())
    return scale, rot, mu_d - scale * rot @ mu_s


def analyse(colmap: str, model: Path, step: str, logs: Path) -> dict:
    """COLMAP's own summary of a model (model_analyzer): registered images, points,
    observations, mean track length, mean reprojection error (px)."""
    out = run(step, [colmap, "model_analyzer", "--path", model], logs)
    fields = {
        "registered_images": r"Registered images:\s*(\d+)",
        "points": r"Points:\s*(\d+)",
        "observations": r"Observations:\s*(\d+)",
        "mean_track_length": r"Mean track length:\s*([0-9.]+)",
        "mean_reprojection_error_px": r"Mean reprojection error:\s*([0-9.]+)",
    }
    stats = {}
    for key, pattern in fields.items():
        m = re.search(pattern, out)
        if m is None:
            raise StepFailed(f"{step}: model_analyzer printed no '{key}' (log: {logs / step}.log)")
        stats[key] = float(m.group(1)) if "." in m.group(1) else int(m.group(1))
    return stats


def to_text(colmap: str, model: Path, text: Path, step: str, logs: Path) -> Path:
    text.mkdir(parents=True, exist_ok=True)
    run(step, [colmap, "model_converter", "--input_path", model, "--output_path", text,
               "--output_type", "TXT"], logs)
    return text


# --------------------------------------------------------------------------- the surface


def surface_points(frame: Path) -> np.ndarray:
    v = PlyData.read(str(frame))["vertex"]
    return np.stack([v["x"], v["y"], v["z"]], axis=1).astype(np.float64)


def spacing_of(points: np.ndarray, tree: cKDTree) -> float:
    """Median distance from a point to its nearest other point (what transcode calls the point
    spacing), on at most 20,000 of them."""
    idx = np.linspace(0, len(points) - 1, min(len(points), 20000)).astype(int)
    d, _ = tree.query(points[idx], k=2)
    return float(np.median(d[:, 1]))


def distances_in_spacings(points: np.ndarray, tree: cKDTree, spacing: float) -> dict:
    if len(points) == 0:
        return {"points": 0}
    d, _ = tree.query(points)
    d = d / spacing
    return {
        "points": int(len(points)),
        "median_spacings": float(np.median(d)),
        "p90_spacings": float(np.percentile(d, 90)),
        "share_within_2_spacings": float(np.mean(d <= 2.0)),
    }


# --------------------------------------------------------------------------- the experiment


def colmap_steps(args, dataset: Path, out: Path, logs: Path, surface, tree, spacing) -> dict:
    colmap = args.colmap
    cams = read_cameras_txt(dataset / "sparse" / "0" / "cameras.txt")
    if len(cams) != 1:
        raise StepFailed(f"{dataset}/sparse/0 has {len(cams)} cameras; the rig has one")
    (model, width, height, params), = cams.values()
    ours = read_images_txt(dataset / "sparse" / "0" / "images.txt")
    work = out / "colmap"
    if work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True)
    db = work / "database.db"
    t0 = time.monotonic()
    run("colmap-features", [
        colmap, "feature_extractor", "--database_path", db, "--image_path", dataset / "images",
        "--ImageReader.camera_model", model, "--ImageReader.single_camera", "1",
        "--ImageReader.camera_params", ",".join(repr(p) for p in params),
        "--SiftExtraction.use_gpu", "0", "--SiftExtraction.num_threads", str(args.threads),
        "--SiftExtraction.peak_threshold", str(args.peak_threshold),
    ], logs)
    run("colmap-matching", [
        colmap, "exhaustive_matcher", "--database_path", db, "--SiftMatching.use_gpu", "0",
        "--SiftMatching.num_threads", str(args.threads),
    ], logs)
    features_s = time.monotonic() - t0
    con = sqlite3.connect(db)
    db_images = {name: (iid, cid) for iid, name, cid in
                 con.execute("select image_id, name, camera_id from images")}
    keypoints = dict(con.execute("select image_id, rows from keypoints"))
    pairs, inliers = con.execute(
        "select count(*), coalesce(sum(rows), 0) from two_view_geometries where rows > 0"
    ).fetchone()
    con.close()
    missing = sorted(set(ours) - set(db_images))
    if missing:
        raise StepFailed(f"colmap-features: COLMAP's database lacks {len(missing)} views, e.g. {missing[0]}")
    features = {
        "keypoints_per_view_median": float(np.median(list(keypoints.values()))),
        "verified_pairs": int(pairs),
        "inlier_matches": int(inliers),
        "seconds": features_s,
    }

    # Our poses under the database's image and camera ids: point_triangulator keeps them fixed.
    known = work / "known"
    known.mkdir()
    (camera_id,) = {cid for _, cid in db_images.values()}
    (known / "cameras.txt").write_text(
        f"{camera_id} {model} {width} {height} {' '.join(repr(p) for p in params)}\n"
    )
    with open(known / "images.txt", "w") as f:
        for name, im in ours.items():
            iid = db_images[name][0]
            f.write(f"{iid} {' '.join(map(repr, im['q']))} {' '.join(map(repr, im['t']))} "
                    f"{camera_id} {name}\n\n")
    (known / "points3D.txt").write_text("")
    tri = work / "triangulated"
    tri.mkdir()
    t0 = time.monotonic()
    run("colmap-triangulation", [
        colmap, "point_triangulator", "--database_path", db, "--image_path", dataset / "images",
        "--input_path", known, "--output_path", tri,
        "--Mapper.ba_refine_focal_length", "0", "--Mapper.ba_refine_principal_point", "0",
        "--Mapper.ba_refine_extra_params", "0", "--Mapper.num_threads", str(args.threads),
    ], logs)
    tri_s = time.monotonic() - t0
    tri_stats = analyse(colmap, tri, "colmap-triangulation-analysis", logs)
    tri_txt = to_text(colmap, tri, work / "triangulated-txt", "colmap-triangulation-txt", logs)
    tri_images = read_images_txt(tri_txt / "images.txt")
    tri_points = read_points3d_txt(tri_txt / "points3D.txt")
    views_seeing = sum(1 for im in tri_images.values() if im["observations"] > 0)
    triangulated = {
        **tri_stats,
        "seconds": tri_s,
        "views": len(ours),
        "views_with_observations": views_seeing,
        "min_observations_per_view": min((im["observations"] for im in tri_images.values()), default=0),
        "surface_distance": distances_in_spacings(tri_points, tree, spacing),
    }

    # A full SfM run without poses, reported beside it and aligned to our cameras.
    sfm = work / "sfm"
    sfm.mkdir()
    t0 = time.monotonic()
    full = {"seconds": None}
    try:
        run("colmap-mapper", [
            colmap, "mapper", "--database_path", db, "--image_path", dataset / "images",
            "--output_path", sfm, "--Mapper.num_threads", str(args.threads),
            # The intrinsics are known (as the paper's renderer-to-COLMAP cameras carry them);
            # the poses are not. COLMAP's default initial-pair thresholds (100 inliers, 16°)
            # find no pair among 44 small rendered views ~30° apart.
            "--Mapper.ba_refine_focal_length", "0", "--Mapper.ba_refine_principal_point", "0",
            "--Mapper.ba_refine_extra_params", "0", "--Mapper.init_min_num_inliers", "30",
            "--Mapper.init_min_tri_angle", "8", "--Mapper.abs_pose_min_num_inliers", "15",
        ], logs)
        full["seconds"] = time.monotonic() - t0
        models = sorted(p for p in sfm.iterdir() if p.is_dir())
        if not models:
            raise StepFailed("colmap-mapper reconstructed no model")
        stats = [(analyse(colmap, m, f"colmap-mapper-analysis-{m.name}", logs), m) for m in models]
        best_stats, best = max(stats, key=lambda s: s[0]["registered_images"])
        full.update(best_stats)
        full["models"] = len(models)
        # Aligned by a least-squares similarity (Umeyama) of the registered cameras' centres onto
        # ours. Not COLMAP 3.8's model_aligner: on these models it returns NaN poses ("Alignment
        # error: -nan") yet reports success, which once gave a bogus 18-spacing distance here.
        raw = to_text(colmap, best, work / "sfm-txt", "colmap-mapper-txt", logs)
        raw_images = read_images_txt(raw / "images.txt")
        ours_c = {name: camera_centre(im["q"], im["t"]) for name, im in ours.items()}
        names = sorted(raw_images)
        theirs = np.array([camera_centre(raw_images[n]["q"], raw_images[n]["t"]) for n in names])
        target = np.array([ours_c[n] for n in names])
        scale, rot, shift = umeyama(theirs, target)
        if not (np.isfinite(scale) and scale > 0 and np.all(np.isfinite(rot))):
            raise StepFailed(f"aligning the pose-free model to our cameras gave scale {scale}")
        residual = np.linalg.norm((scale * (rot @ theirs.T)).T + shift - target, axis=1)
        centre = np.mean(list(ours_c.values()), axis=0)
        rig_radius = float(np.median([np.linalg.norm(c - centre) for c in ours_c.values()]))
        aligned_points = (scale * (rot @ read_points3d_txt(raw / "points3D.txt").T)).T + shift
        full["surface_distance_after_alignment"] = distances_in_spacings(
            aligned_points, tree, spacing)
        full["alignment"] = {
            "rig_radius_spacings": rig_radius / spacing,
            "camera_centre_residual_median_spacings": float(np.median(residual)) / spacing,
            "camera_centre_residual_max_spacings": float(np.max(residual)) / spacing,
            "camera_centre_residual_median_share_of_radius": float(np.median(residual)) / rig_radius,
        }
    except StepFailed as e:
        # The pose-free run is reported beside the experiment, never used by it: its failure
        # is recorded, not fatal.
        full["failed"] = str(e)
        print(f"   (pose-free SfM: {str(e).splitlines()[0]})", flush=True)

    return {"features": features, "triangulated": triangulated, "full_sfm": full,
            "triangulated_model": str(tri)}


def first_reaching(curve: list[dict], target: float) -> dict | None:
    for p in curve:
        if p["psnr_black"] >= target:
            return {"iteration": p["iteration"], "elapsed_s": p["elapsed_s"]}
    return None


def compare(report: dict) -> dict:
    runs = {r["init"]["mode"]: r for r in report["runs"]}
    sparse, surface = runs["sparse"], runs["surface"]
    final_sfm = sparse["metrics"]["psnr_black"]
    target = final_sfm - 0.5
    models = {}
    for mode, r in runs.items():
        m = r["metrics"]
        models[mode] = {
            "init_source": r["init"]["source"],
            "init_splats": r["init"]["splats"],
            "splats": m["splats"],
            "iterations": r["iterations"],
            "train_seconds": r["train_seconds"],
            "psnr_black": m["psnr_black"],
            "psnr_white": m["psnr_white"],
            "masked_psnr_black": m["masked_psnr_black"],
            "masked_psnr_white": m["masked_psnr_white"],
            "ssim_black": m["ssim_black"],
            "ssim_white": m["ssim_white"],
            "far_share": m["surface"].get("far_share") if m.get("surface") else None,
            "interior_share": m["surface"].get("interior_share") if m.get("surface") else None,
            "floater_share": m["surface"]["floater_share"] if m.get("surface") else None,
            "floaters": m["surface"]["floaters"] if m.get("surface") else None,
            "first_within_0_5_db_of_sfm_final": first_reaching(r["heldout_curve"], target),
            "curve": r["heldout_curve"],
            "model_bytes": r["model_bytes"],
        }
    a = models["surface"]["first_within_0_5_db_of_sfm_final"]
    b = models["sparse"]["first_within_0_5_db_of_sfm_final"]
    speedup = None
    if a and b and a["iteration"] > 0:
        speedup = {
            "steps": b["iteration"] / a["iteration"],
            "seconds": b["elapsed_s"] / a["elapsed_s"] if a["elapsed_s"] > 0 else None,
        }
    return {
        "target_psnr_black": target,
        "models": models,
        "surface_faster_by": speedup,
        # Surface init above the target before its first step: no finite ratio.
        "surface_at_target_before_training": bool(a and a["iteration"] == 0),
    }


def markdown(result: dict) -> str:
    c, tri, full, feat = (result["comparison"], result["colmap"]["triangulated"],
                          result["colmap"]["full_sfm"], result["colmap"]["features"])
    lines = [
        f"# Surface init against COLMAP SfM init: {Path(result['frame']).name}",
        "",
        f"Frame: {result['frame_points']:,} points; {result['views']} training views of "
        f"{result['resolution']}²; {result['iterations']} steps, held-out scored every "
        f"{result['eval_every']} steps. Command: `{result['command']}`.",
        "",
        "## COLMAP",
        "",
        f"- Features: median {feat['keypoints_per_view_median']:.0f} SIFT keypoints a view, "
        f"{feat['verified_pairs']} verified pairs, {feat['inlier_matches']} inlier matches "
        f"({feat['seconds']:.0f} s).",
        f"- Triangulation with our poses fixed: {tri['registered_images']} images, "
        f"{tri['views_with_observations']} of {tri['views']} views with observations, "
        f"{tri['points']} points, mean track length {tri['mean_track_length']:.2f}, mean "
        f"reprojection error {tri['mean_reprojection_error_px']:.3f} px; distance to the surface: "
        f"median {tri['surface_distance'].get('median_spacings', float('nan')):.2f} spacings, "
        f"{100 * tri['surface_distance'].get('share_within_2_spacings', 0):.0f} % within 2.",
    ]
    if "failed" in full:
        lines.append(f"- Full SfM without poses: failed ({full['failed'].splitlines()[0]}).")
    else:
        d = full.get("surface_distance_after_alignment", {})
        lines.append(
            f"- Full SfM without poses: {full['registered_images']} of {tri['views']} images "
            f"registered ({full['models']} model(s)), {full['points']} points, mean reprojection "
            f"error {full['mean_reprojection_error_px']:.3f} px; after alignment to our cameras, "
            f"median distance to the surface {d.get('median_spacings', float('nan')):.2f} spacings "
            f"({full['seconds']:.0f} s).")
        a = full.get("alignment")
        if a:
            lines.append(
                f"- Alignment: a least-squares similarity of the registered cameras' centres onto "
                f"ours leaves them a median {a['camera_centre_residual_median_spacings']:.1f} "
                f"spacings ({100 * a['camera_centre_residual_median_share_of_radius']:.2f} % of the "
                f"rig's radius of {a['rig_radius_spacings']:.0f} spacings; worst "
                f"{a['camera_centre_residual_max_spacings']:.1f}) from ours.")
    lines += [
        "",
        "## Training",
        "",
        "| init | splats | held-out PSNR black / white (dB) | masked black / white (dB) | SSIM black | "
        "opacity beyond 2 spacings (inside the object / floaters) | "
        "first step within 0.5 dB of SfM's final | training time |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for mode in ("surface", "sparse"):
        m = c["models"][mode]
        first = m["first_within_0_5_db_of_sfm_final"]
        first_s = f"{first['iteration']} ({first['elapsed_s']:.0f} s)" if first else "never"
        pct = lambda x: "–" if x is None else f"{100 * x:.1f} %"
        floats = f"{pct(m['far_share'])} ({pct(m['interior_share'])} / {pct(m['floater_share'])})"
        lines.append(
            f"| {'surface' if mode == 'surface' else 'COLMAP points3D'} | {m['splats']:,} | "
            f"{m['psnr_black']:.2f} / {m['psnr_white']:.2f} | {m['masked_psnr_black']:.2f} / "
            f"{m['masked_psnr_white']:.2f} | {m['ssim_black']:.4f} | {floats} | {first_s} | "
            f"{m['train_seconds']:.0f} s |")
    s = c["surface_faster_by"]
    target = f"SfM's final PSNR − 0.5 dB ({c['target_psnr_black']:.2f} dB)"
    b = c["models"]["sparse"]["first_within_0_5_db_of_sfm_final"]
    sfm_at = f"COLMAP init needs {b['iteration']} steps ({b['elapsed_s']:.0f} s)" if b else ""
    if s:
        verdict = (f"Surface init reaches {target} {s['steps']:.1f}× sooner in steps and "
                   f"{s['seconds']:.1f}× sooner in training time; {sfm_at}.")
    elif c["surface_at_target_before_training"]:
        verdict = f"Surface init is above {target} before its first step; {sfm_at}."
    else:
        verdict = f"No ×N figure: the surface run never reached {target}."
    lines += ["", verdict]
    lines += ["", "| step | surface black (dB) | SfM black (dB) | surface white | SfM white | "
              "surface splats | SfM splats |", "|---|---|---|---|---|---|---|"]
    cs = {p["iteration"]: p for p in c["models"]["sparse"]["curve"]}
    for p in c["models"]["surface"]["curve"]:
        q = cs.get(p["iteration"])
        if q:
            lines.append(f"| {p['iteration']} | {p['psnr_black']:.2f} | {q['psnr_black']:.2f} | "
                         f"{p['psnr_white']:.2f} | {q['psnr_white']:.2f} | {p['splats']:,} | "
                         f"{q['splats']:,} |")
    if result.get("pictures"):
        lines += ["", "Held-out view, left to right: reference, surface init, COLMAP init:", ""]
        lines += [f"![{Path(p).stem}]({os.path.relpath(p, result['out'])})" for p in result["pictures"]]
    return "\n".join(lines) + "\n"


def check(result: dict) -> list[str]:
    """The assertions CI makes (docs/paper-experiment.md)."""
    problems = []
    tri = result["colmap"]["triangulated"]
    if tri["registered_images"] != tri["views"]:
        problems.append(f"triangulation registered {tri['registered_images']} of {tri['views']} views")
    if tri["views_with_observations"] != tri["views"]:
        problems.append(f"only {tri['views_with_observations']} of {tri['views']} views see a "
                        "triangulated point")
    med = tri["surface_distance"].get("median_spacings")
    if med is None or not med < 2.0:
        problems.append(f"triangulated points' median distance to the surface is {med} spacings (≥ 2)")
    for mode, m in result["comparison"]["models"].items():
        if m["iterations"] != result["iterations"] or not math.isfinite(m["psnr_black"]):
            problems.append(f"the {mode} training did not run its {result['iterations']} steps")
        if len(m["curve"]) < 2:
            problems.append(f"the {mode} training has no held-out curve")
    full = result["colmap"]["full_sfm"]
    if "failed" not in full:
        a = full.get("alignment", {})
        d = full.get("surface_distance_after_alignment", {}).get("median_spacings")
        if not (math.isfinite(a.get("camera_centre_residual_median_spacings", math.nan))
                and d is not None and math.isfinite(d)):
            problems.append(f"the pose-free model's alignment is not finite ({a}, distance {d})")
    sparse = result["comparison"]["models"]["sparse"]
    if sparse["init_source"] != "colmap" or sparse["init_splats"] != tri["points"]:
        problems.append(f"the sparse model did not start from COLMAP's {tri['points']} points "
                        f"({sparse['init_splats']} from {sparse['init_source']})")
    return problems


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, required=True, help="output folder")
    ap.add_argument("--transcode", default=str(REPO / "target" / "release" / "transcode"))
    ap.add_argument("--colmap", default="colmap")
    ap.add_argument("--frame", type=Path, help="a plenoptic PLY of the user's (default: synth)")
    ap.add_argument("--mesh", type=Path, default=SPIDER, help="the mesh synth samples")
    ap.add_argument("--points", type=int, default=1_000_000)
    ap.add_argument("--grid", type=int, default=600)
    ap.add_argument("--resolution", type=int, default=512)
    ap.add_argument("--iterations", type=int, default=6000)
    ap.add_argument("--eval-every", type=int, default=250)
    ap.add_argument("--splats", type=int, help="surface splats (default: one per point)")
    ap.add_argument("--peak-threshold", type=float, default=0.002,
                    help="SIFT peak threshold (COLMAP's default 0.0067 finds few features on "
                         "dark rendered views)")
    ap.add_argument("--threads", type=int, default=os.cpu_count() or 2)
    ap.add_argument("--small", action="store_true",
                    help="CI's version: 40k-point frame, 512² views, 300 steps")
    ap.add_argument("--check", action="store_true", help="fail unless CI's assertions hold")
    args = ap.parse_args()
    if args.small:
        args.points, args.grid, args.resolution, args.iterations, args.eval_every = (
            200_000, 250, 512, 300, 100)
    if shutil.which(args.colmap) is None:
        print(f"error: COLMAP ({args.colmap}) is not installed: `apt-get install colmap` "
              "(Debian's package, 3.8) or pass --colmap PATH", file=sys.stderr)
        return 2
    out = args.out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    logs = out / "logs"
    # A result of an earlier run in OUT must not outlive a failure of this one.
    for stale in ("paper.json", "paper.md"):
        (out / stale).unlink(missing_ok=True)
    tc = args.transcode
    try:
        if args.frame:
            frame = args.frame.resolve()
        else:
            frame = out / "frame.ply"
            run("synth", [tc, "synth", "--mesh", args.mesh, "--points", args.points, "--grid",
                          args.grid, "--out", frame], logs)
        dataset = out / "dataset"
        if dataset.exists():
            shutil.rmtree(dataset)
        run("views", [tc, "views", frame, "--resolution", args.resolution, "--out", dataset], logs)
        surface = surface_points(frame)
        tree = cKDTree(surface)
        spacing = spacing_of(surface, tree)
        col = colmap_steps(args, dataset, out, logs, surface, tree, spacing)
        tri = col["triangulated"]
        if tri["points"] < 100:
            raise StepFailed(f"colmap-triangulation: only {tri['points']} points; no comparison is "
                             "built on so thin an SfM (see logs/colmap-*.log)")
        runs = out / "runs"
        if runs.exists():
            shutil.rmtree(runs)
        # Surface init is the run's main model; the compared one starts from COLMAP's points.
        cmd = [tc, "run", frame, "--resolution", args.resolution, "--init", "surface",
               "--points3d", col["triangulated_model"], "--compare-init", "--iterations",
               args.iterations, "--eval-every", args.eval_every, "--out", runs, "--quiet"]
        if args.splats:
            cmd += ["--splats", args.splats]
        run("train", cmd, logs)
        # Both models trained on exactly the views COLMAP saw.
        names = sorted(p.name for p in (dataset / "images").iterdir())
        _, mismatch, errors = filecmp.cmpfiles(dataset / "images", runs / "dataset" / "images", names,
                                               shallow=False)
        if mismatch or errors:
            raise StepFailed(f"train: the run's views differ from COLMAP's ({(mismatch + errors)[:3]})")
        report = json.loads((runs / "report" / "report.json").read_text())
        # One held-out camera: the reference and the surface model's render are the viewer's
        # pictures beside the report; the COLMAP-initialised model is rendered from it here.
        viewer = runs / "report" / "viewer"
        view = sorted((viewer / "views").glob("*-reference.png"))[0].name.replace("-reference", "")
        stem = view.removesuffix(".png")
        sparse_pictures = runs / "pictures-sparse"
        run("render-sparse", [tc, "render", runs / "model" / "splats-sparse.ply", "--colmap",
                              viewer / "heldout", "--images", view, "--out", sparse_pictures], logs)
        pictures = [viewer / "views" / f"{stem}-reference.png", viewer / "views" / f"{stem}-render.png",
                    sparse_pictures / view]
        result = {
            "command": " ".join(sys.argv),
            "out": str(out),
            "frame": str(frame),
            "frame_points": int(len(surface)),
            "point_spacing": spacing,
            "views": len(names),
            "resolution": args.resolution,
            "iterations": args.iterations,
            "eval_every": args.eval_every,
            "colmap": col,
            "comparison": compare(report),
            "pictures": [str(p) for p in pictures],
        }
    except StepFailed as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    (out / "paper.json").write_text(json.dumps(result, indent=2))
    md = markdown(result)
    (out / "paper.md").write_text(md)
    print(md)
    if args.check:
        problems = check(result)
        for p in problems:
            print(f"check failed: {p}", file=sys.stderr)
        if problems:
            return 1
        print("all checks passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
