#!/usr/bin/env bash
# The GPU machine's check (issue 20), run there from the repository's root with .devpkg and .gl
# carried (tools/device/pack.sh; .gl holds the Vulkan and GL loaders as Debian packages, fetched
# with `apt-get download libvulkan1 libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2`):
# TLED steps on the CPU and the GPU up to a million cells, carving on three rigs, and the main job
# on the GPU backend and on 2, 4 and all cores (taskset + RAYON_NUM_THREADS), with mask files and
# segmenting. Each step has a timeout inside LIMIT seconds (default 470); everything lands in
# $OUT/results.tar.gz, the step log in $OUT/log.txt.
set -u
START=$(date +%s); LIMIT=${LIMIT:-470}
R=/tmp/res; mkdir -p $R
for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
mkdir -p /usr/share/fonts/truetype/dejavu && cp .devpkg/DejaVuSans.ttf /usr/share/fonts/truetype/dejavu/
mkdir -p /tmp/pkg && tar -C /tmp/pkg -xJf .devpkg/pkg.tar.xz
export LD_LIBRARY_PATH=/tmp/pkg/lib
icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
[ -f $icd ] && export VK_DRIVER_FILES=$icd
H=/tmp/pkg/hullcut
left() { echo $(( LIMIT - ($(date +%s) - START) )); }
step() { # step NAME SECONDS CMD...
  local name=$1 want=$2; shift 2; local l; l=$(left); local t=$(( want < l - 20 ? want : l - 20 ))
  if [ $t -lt 10 ]; then echo "== skip $name (no time)" >> $R/log.txt; return; fi
  echo "== $(date +%T) $name (timeout $t)" >> $R/log.txt
  local s; s=$(date +%s); timeout $t "$@" > $R/$name.log 2>&1; local rc=$?
  echo "   rc=$rc $(( $(date +%s) - s )) s" >> $R/log.txt
}
{ nvidia-smi -L; nproc; lscpu | grep -E 'Model name|^CPU\(s\)'; free -g; } > $R/machine.txt 2>&1
$H gpu-info > $R/gpu-info.txt 2>&1
step backends 150 $H bench backends --out $R/backends
step run-gpu16 45 $H run --backend gpu --rrd /tmp/g16.rrd --report $R/run-gpu16.json
step run-cpu16 45 $H run --rrd /tmp/c16.rrd --report $R/run-cpu16.json
step run-cpu4 45 taskset -c 0-3 env RAYON_NUM_THREADS=4 $H run --rrd /tmp/c4.rrd --report $R/run-cpu4.json
step run-cpu2 45 taskset -c 0-1 env RAYON_NUM_THREADS=2 $H run --rrd /tmp/c2.rrd --report $R/run-cpu2.json
step run-gpu2 45 taskset -c 0-1 env RAYON_NUM_THREADS=2 $H run --backend gpu --rrd /tmp/g2.rrd --report $R/run-gpu2.json
step hull 220 $H bench hull --out $R/hull
step run-seg16 60 $H run --masks segment --rrd /tmp/s16.rrd --report $R/run-seg16.json
step run-seg2 60 taskset -c 0-1 env RAYON_NUM_THREADS=2 $H run --masks segment --rrd /tmp/s2.rrd --report $R/run-seg2.json
tar -C /tmp -czf "$OUT/results.tar.gz" res
cp $R/log.txt "$OUT/log.txt"
