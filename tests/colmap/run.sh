#!/usr/bin/env bash
# CI's small version of the paper's experiment with the real COLMAP (docs/paper-experiment.md):
# installs Debian's colmap when it is missing, runs bench/paper_colmap.py --small --check and
# fails when any of its assertions fails (every view registered and seeing triangulated points,
# the triangulated points within 2 point spacings of the surface, both trainings run).
# Usage: tests/colmap/run.sh TRANSCODE_BIN PYTHON   (PYTHON: a venv's python, to pip into)
set -euo pipefail
transcode="$(realpath "$1")"
python="$2"
here="$(cd "$(dirname "$0")" && pwd)"
repo="$(cd "$here/../.." && pwd)"

bash "$repo/.ci/ensure-debian-command" colmap colmap
# sed, not head: head would close the pipe early and COLMAP, killed by SIGPIPE, fail the script
# under pipefail (exit 141).
colmap -h 2> /dev/null | sed -n 1p
"$python" -m pip install --quiet --disable-pip-version-check -r "$repo/bench/requirements.txt"

out="$(mktemp -d)"
trap 'rm -rf "$out"' EXIT
"$python" "$repo/bench/paper_colmap.py" --small --check \
    --transcode "$transcode" --out "$out/paper"
