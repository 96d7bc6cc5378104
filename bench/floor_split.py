#!/usr/bin/env python3
"""Where a model of the floor demo keeps its splats: on the small checkered ball or on the wide
plain floor (issue 15: a large flat region and a small detailed object should end with most of
the splats on the object).

    transcode demo --layout floor --out OUT
    python3 bench/floor_split.py OUT [OUT2 ...] [--regions]
    transcode run demo.ply --out OUT ...; python3 bench/floor_split.py OUT --input demo.ply

For each output folder it counts the input's points (OUT/input/demo.ply, or --input) and the
model's splats (OUT/model/splats.ply) on each solid and prints both splits. A point or splat
belongs to the ball when it is nearer the ball's surface than the floor's (the scene's own rule,
plenoptic-scenes/src/demo.rs, `Solids::on_sphere`). With --regions it also splits the floor's
splats by the box's faces (the top's and the underside's interiors, their rims within 3 voxels
of a side, the sides, the top round the ball) and describes the splats on the box's long edges
(within 1.5 voxels of two faces): how many, their median standard deviations, and how many lie
along their edge (longest axis within 26 degrees of it), as in docs/benchmarks/budget.md,
session 41. Needs numpy and plyfile (bench/requirements.txt).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from plyfile import PlyData

# The floor layout's solids as fractions of the voxel grid (plenoptic-scenes/src/demo.rs,
# `Solids::new` for `DemoLayout::Floor`); the demo's coordinates are voxel units.
FLOOR_LO = np.array([0.05, 0.30, 0.05])
FLOOR_HI = np.array([0.95, 0.36, 0.95])
BALL_CENTRE = np.array([0.5, 0.47, 0.5])
BALL_RADIUS = 0.12


def on_ball(p: np.ndarray, grid: float) -> np.ndarray:
    """Whether each row of `p` is nearer the ball's surface than the floor's."""
    ball = np.abs(np.linalg.norm(p - BALL_CENTRE * grid, axis=1) - BALL_RADIUS * grid)
    centre = 0.5 * (FLOOR_LO + FLOOR_HI) * grid
    half = 0.5 * (FLOOR_HI - FLOOR_LO) * grid
    q = np.abs(p - centre) - half
    floor = np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)
    return ball < np.abs(floor)


def positions(path: Path) -> np.ndarray:
    v = PlyData.read(str(path))["vertex"]
    return np.stack([np.asarray(v["x"]), np.asarray(v["y"]), np.asarray(v["z"])], axis=1)


def axes(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Each splat's standard deviations (exp of the PLY's log scales) and rotation matrix (the
    PLY's rot_0..3 as w, x, y, z, normalised)."""
    v = PlyData.read(str(path))["vertex"]
    sd = np.exp(np.stack([np.asarray(v[f"scale_{i}"]) for i in range(3)], axis=1))
    q = np.stack([np.asarray(v[f"rot_{i}"]) for i in range(4)], axis=1).astype(np.float64)
    w, x, y, z = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
    rot = np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], 1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], 1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], 1),
        ],
        axis=1,
    )
    return sd, rot


def floor_regions(p: np.ndarray, ball: np.ndarray, grid: float) -> dict[str, int]:
    """The floor's splats (rows of `p` not on the `ball`) by the face of the box they are
    nearest."""
    lo, hi = FLOOR_LO * grid, FLOOR_HI * grid
    f = p[~ball]
    d_top, d_under = np.abs(f[:, 1] - hi[1]), np.abs(f[:, 1] - lo[1])
    d_side = np.minimum.reduce(
        [np.abs(f[:, 0] - lo[0]), np.abs(f[:, 0] - hi[0]), np.abs(f[:, 2] - lo[2]), np.abs(f[:, 2] - hi[2])]
    )
    nearest = np.minimum.reduce([d_top, d_under, d_side])
    top = d_top == nearest
    under = (d_under == nearest) & ~top
    side = ~top & ~under
    rim = d_side < 3.0
    centre = BALL_CENTRE * grid
    round_ball = np.hypot(f[:, 0] - centre[0], f[:, 2] - centre[2]) < 0.6 * BALL_RADIUS * grid + 3.0
    return {
        "top interior": int((top & ~rim & ~round_ball).sum()),
        "top round the ball": int((top & round_ball).sum()),
        "top rim": int((top & rim).sum()),
        "sides": int(side.sum()),
        "underside interior": int((under & ~rim).sum()),
        "underside rim": int((under & rim).sum()),
    }


def long_edges(p: np.ndarray, sd: np.ndarray, rot: np.ndarray, grid: float) -> dict[str, float]:
    """The floor's splats (rows of `p`, `sd`, `rot`) on the box's eight long edges (within 1.5
    voxels of two faces, more than 3 from the third): count, median standard deviations (least, middle, largest) and the share
    whose longest axis is within 26 degrees of its edge."""
    lo, hi = FLOOR_LO * grid, FLOOR_HI * grid
    d = np.minimum(np.abs(p - lo), np.abs(p - hi))
    along_z = (d[:, 0] < 1.5) & (d[:, 1] < 1.5) & (d[:, 2] > 3.0)
    along_x = (d[:, 2] < 1.5) & (d[:, 1] < 1.5) & (d[:, 0] > 3.0)
    edge = along_z | along_x
    longest = rot[np.arange(len(p)), :, np.argmax(sd, axis=1)]
    direction = np.where(along_z[:, None], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
    along = np.abs((longest * direction).sum(axis=1)) > 0.9
    n = int(edge.sum())
    med = np.median(np.sort(sd[edge], axis=1), axis=0) if n else np.zeros(3)
    return {
        "splats": n,
        "sd least": round(float(med[0]), 3),
        "sd middle": round(float(med[1]), 3),
        "sd largest": round(float(med[2]), 3),
        "share along the edge": round(float(along[edge].mean()) if n else 0.0, 3),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("outs", nargs="+", type=Path, help="`transcode demo --layout floor` folders")
    ap.add_argument("--grid", type=float, default=128.0, help="the demo's --grid (default 128)")
    ap.add_argument("--input", type=Path, help="the input cloud, for folders without input/demo.ply")
    ap.add_argument("--regions", action="store_true", help="split the floor's splats by face too")
    args = ap.parse_args()
    rows = []
    for out in args.outs:
        row = {"out": str(out)}
        model = out / "model/splats.ply"
        for name, path in (("input", args.input or out / "input/demo.ply"), ("model", model)):
            if not path.is_file():
                print(f"error: {path} does not exist", file=sys.stderr)
                return 1
            p = positions(path)
            ball = on_ball(p, args.grid)
            row[name] = {"total": int(ball.size), "ball": int(ball.sum())}
        if args.regions:
            # `p` and `ball` are the model's, the loop's last.
            sd, rot = axes(model)
            row["floor"] = floor_regions(p, ball, args.grid)
            row["long edges"] = long_edges(p[~ball], sd[~ball], rot[~ball], args.grid)
        rows.append(row)
        i, m = row["input"], row["model"]
        print(
            f"{out}: input {i['total']} points, {i['ball']} on the ball "
            f"({100 * i['ball'] / i['total']:.1f} %); model {m['total']} splats, {m['ball']} on "
            f"the ball ({100 * m['ball'] / m['total']:.1f} %): the ball kept "
            f"{100 * m['ball'] / i['ball']:.0f} % of its points' count, the floor "
            f"{100 * (m['total'] - m['ball']) / (i['total'] - i['ball']):.0f} %"
        )
        if args.regions:
            print("  floor: " + ", ".join(f"{k} {v}" for k, v in row["floor"].items()))
            e = row["long edges"]
            print(
                f"  long edges: {e['splats']} splats, median sd {e['sd least']} / "
                f"{e['sd middle']} / {e['sd largest']}, {100 * e['share along the edge']:.0f} % "
                "along their edge"
            )
    print(json.dumps(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
