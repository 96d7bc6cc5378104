#!/usr/bin/env python3
"""Where a model of the floor demo keeps its splats: on the small checkered ball or on the wide
plain floor (issue 15: a large flat region and a small detailed object should end with most of
the splats on the object).

    transcode demo --layout floor --out OUT
    python3 bench/floor_split.py OUT [OUT2 ...]

For each output folder it counts the input's points (OUT/input/demo.ply) and the model's splats
(OUT/model/splats.ply) on each solid and prints both splits. A point or splat belongs to the
ball when it is nearer the ball's surface than the floor's (the scene's own rule,
plenoptic-scenes/src/demo.rs, `Solids::on_sphere`). Needs numpy and plyfile
(bench/requirements.txt).
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


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("outs", nargs="+", type=Path, help="`transcode demo --layout floor` folders")
    ap.add_argument("--grid", type=float, default=128.0, help="the demo's --grid (default 128)")
    args = ap.parse_args()
    rows = []
    for out in args.outs:
        row = {"out": str(out)}
        for name, rel in (("input", "input/demo.ply"), ("model", "model/splats.ply")):
            path = out / rel
            if not path.is_file():
                print(f"error: {path} does not exist", file=sys.stderr)
                return 1
            ball = on_ball(positions(path), args.grid)
            row[name] = {"total": int(ball.size), "ball": int(ball.sum())}
        rows.append(row)
        i, m = row["input"], row["model"]
        print(
            f"{out}: input {i['total']} points, {i['ball']} on the ball "
            f"({100 * i['ball'] / i['total']:.1f} %); model {m['total']} splats, {m['ball']} on "
            f"the ball ({100 * m['ball'] / m['total']:.1f} %): the ball kept "
            f"{100 * m['ball'] / i['ball']:.0f} % of its points' count, the floor "
            f"{100 * (m['total'] - m['ball']) / (i['total'] - i['ball']):.0f} %"
        )
    print(json.dumps(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
