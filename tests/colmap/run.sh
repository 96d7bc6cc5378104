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

if ! command -v colmap > /dev/null; then
    echo "COLMAP is missing: installing Debian's colmap package"
    if [ "$(id -u)" = 0 ]; then
        apt_get=(apt-get)
    elif command -v sudo > /dev/null; then
        apt_get=(sudo -n apt-get)
    else
        echo "error: COLMAP is not installed and neither root nor sudo can install it" >&2
        exit 1
    fi
    DEBIAN_FRONTEND=noninteractive "${apt_get[@]}" update -qq
    DEBIAN_FRONTEND=noninteractive "${apt_get[@]}" install -y -qq colmap
    command -v colmap > /dev/null || {
        echo "error: installing colmap did not give a colmap command" >&2
        exit 1
    }
fi
colmap -h 2> /dev/null | head -1
"$python" -m pip install --quiet --disable-pip-version-check -r "$repo/bench/requirements.txt"

out="$(mktemp -d)"
trap 'rm -rf "$out"' EXIT
"$python" "$repo/bench/paper_colmap.py" --small --check \
    --transcode "$transcode" --out "$out/paper"
