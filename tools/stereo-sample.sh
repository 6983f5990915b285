#!/usr/bin/env bash
# Lays out OpenCV's sample stereo chessboard photos (Debian package opencv-doc) as a hullcut
# calibration image tree: OUT/left/NN.jpg and OUT/right/NN.jpg (same name = simultaneous views).
# The board has 9x6 inner corners; its square size is not documented (we assume 25 mm).
#
# Usage: tools/stereo-sample.sh OUT
set -euo pipefail
out=${1:?usage: tools/stereo-sample.sh OUT}
src=${OPENCV_SAMPLES:-/usr/share/doc/opencv-doc/examples/data}
if [ ! -e "$src/left01.jpg" ]; then
    echo "stereo-sample: $src/left01.jpg not found; run tools/setup.sh (installs opencv-doc)" >&2
    exit 1
fi
mkdir -p "$out/left" "$out/right"
for f in "$src"/left[0-9][0-9].jpg; do
    n=$(basename "$f" .jpg); n=${n#left}
    cp -f "$f" "$out/left/$n.jpg"
    [ -e "$src/right$n.jpg" ] && cp -f "$src/right$n.jpg" "$out/right/$n.jpg"
done
echo "stereo-sample: $(ls "$out/left" | wc -l) left and $(ls "$out/right" | wc -l) right images in $out"
