#!/usr/bin/env bash
# Packs the built `hullcut` binary for a GPU machine that has no OpenCV and no network (the
# `device` machines of our workplace): the binary stripped, the shared libraries it loads from
# Debian (OpenCV and what it needs, about 40 MB), and small stand-ins for the heavy libraries
# OpenCV links but `hullcut run` and the benches never use (GDAL, FFmpeg, GStreamer, libgphoto2,
# libdc1394: tools/device/stub-libs.py; a stand-in that is called prints its name and returns 0),
# as .devpkg/pkg.tar.xz (about 19 MB) beside tools/device/check.sh and the charts' font.
#
# Usage: cargo build -p hullcut && tools/device/pack.sh [BINARY]   (then carry .devpkg and .gl;
# .git/info/exclude should name /.devpkg/ and /.gl/, see check.sh)
set -euo pipefail
cd "$(dirname "$0")/../.."
bin=${1:-target/debug/hullcut}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
python3 tools/device/stub-libs.py "$bin" "$work/lib"
strip -o "$work/hullcut" "$bin"
mkdir -p .devpkg
tar -C "$work" -cf - . | xz -6 -T0 > .devpkg/pkg.tar.xz
cp tools/device/check.sh .devpkg/run.sh
cp /usr/share/fonts/truetype/dejavu/DejaVuSans.ttf .devpkg/
ls -la .devpkg
