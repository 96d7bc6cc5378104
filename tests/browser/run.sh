#!/usr/bin/env bash
# The splat viewer in a real browser (docs/viewer.md): makes a small model with the demo, renders
# its held-out cameras with the CPU rasteriser (`transcode render`), serves the output folder
# with `transcode view`, and has headless Chromium (Debian's package, software WebGL) open the
# viewer at each camera; tests/browser/driver.py compares the screenshots with the CPU renders,
# checks that the page logs no error, and that deliberately broken viewers fail.
#
# Usage: tests/browser/run.sh TRANSCODE_BIN [PYTHON]
#   PYTHON: an interpreter with tests/browser/requirements.txt (default: a fresh venv).
#   SHOTS=DIR keeps the screenshots; BENCH=FRAMES also measures the frame rate while orbiting.
# Fails, never skips, when Chromium cannot be installed or started.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
transcode="$(realpath "${1:?usage: run.sh TRANSCODE_BIN [PYTHON]}")"
python="${2:-}"

bash "$here/../../.ci/ensure-debian-command" chromium chromium --no-install-recommends
chromium_bin="$(command -v chromium)"
"$chromium_bin" --version 2> /dev/null

work="$(mktemp -d)"
server=""
cleanup() {
    if [ -n "$server" ]; then
        kill "$server" 2> /dev/null || true
        wait "$server" 2> /dev/null || true
    fi
    rm -rf "$work"
}
trap cleanup EXIT

if [ -z "$python" ]; then
    python3 -m venv "$work/venv"
    "$work/venv/bin/pip" install --quiet --disable-pip-version-check -r "$here/requirements.txt"
    python="$work/venv/bin/python"
fi

echo "-- a small model (the demo at 256 px, 10 s of training)"
"$transcode" demo --out "$work/demo" --grid 64 --resolution 256 --time-budget 10 --quiet
viewer="$work/demo/report/viewer"
echo "-- the CPU rasteriser's renders of the viewer's model at the held-out cameras"
"$transcode" render "$viewer/model.spz" --colmap "$viewer/heldout" --out "$work/cpu" 2> /dev/null
views="$(find "$work/cpu" -name '*.png' -printf '%f\n' | sed 's/\.png$//' | sort | paste -sd, -)"

echo "-- transcode view"
"$transcode" view "$work/demo" --port 0 > "$work/view.log" 2>&1 &
server=$!
url=""
for _ in $(seq 100); do
    url="$(grep -o 'http://[^ ]*' "$work/view.log" | head -n 1 || true)"
    [ -n "$url" ] && break
    sleep 0.1
done
if [ -z "$url" ]; then
    echo "error: transcode view printed no address:" >&2
    cat "$work/view.log" >&2
    exit 1
fi
echo "$url"
base="${url%/report/report.html}"

extra=()
[ -n "${SHOTS:-}" ] && extra+=(--shots "$SHOTS")
[ -n "${BENCH:-}" ] && extra+=(--bench "$BENCH")
"$python" "$here/driver.py" --chromium "$chromium_bin" \
    --url "$base/report/viewer/index.html" \
    --file-url "file://$work/demo/report/report.html" \
    --cpu "$work/cpu" --views "$views" "${extra[@]}"
