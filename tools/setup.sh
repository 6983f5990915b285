#!/usr/bin/env bash
# Installs the system packages hullcut needs on Debian (idempotent: checks before it installs).
#
#   libopencv-dev clang libclang-dev  build the `opencv` crate (calibration, capture)
#   opencv-doc                        OpenCV's sample photos, used by tests (stereo chessboards)
#   mesa-vulkan-drivers               software Vulkan (lavapipe) for GPU tests without a GPU
#   pkg-config                        lets the opencv crate find the library
#   fonts-dejavu-core                 the font of the benchmark charts (hullcut bench)
#
# Usage: tools/setup.sh [--with-viewer]   (--with-viewer also installs the rerun viewer from PyPI)
set -euo pipefail

packages=(libopencv-dev clang libclang-dev opencv-doc mesa-vulkan-drivers pkg-config fonts-dejavu-core)
missing=()
for p in "${packages[@]}"; do
    if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
        missing+=("$p")
    fi
done

if ((${#missing[@]})); then
    echo "setup: installing ${missing[*]}"
    sudo_cmd=""
    if [ "$(id -u)" -ne 0 ]; then sudo_cmd="sudo"; fi
    export DEBIAN_FRONTEND=noninteractive
    $sudo_cmd apt-get update -q
    $sudo_cmd apt-get install -y -q --no-install-recommends "${missing[@]}"
else
    echo "setup: system packages already installed"
fi

# opencv-doc ships the sample images gzip-compressed on some Debian releases; tests read plain files.
doc=/usr/share/doc/opencv-doc/examples/data
if [ -d "$doc" ]; then
    for gz in "$doc"/left*.jpg.gz "$doc"/right*.jpg.gz; do
        [ -e "$gz" ] || continue
        [ -e "${gz%.gz}" ] || { sudo_cmd=""; [ "$(id -u)" -ne 0 ] && sudo_cmd="sudo"; $sudo_cmd gunzip -k "$gz"; }
    done
fi

if [ "${1:-}" = "--with-viewer" ]; then
    if ! python3 -c "import rerun" 2>/dev/null; then
        echo "setup: installing the rerun viewer (rerun-sdk==0.36.3) from PyPI"
        python3 -m pip install --quiet "rerun-sdk==0.36.3"
    fi
fi
