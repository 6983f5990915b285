#!/usr/bin/env bash
# The labelling's speed on the GPU machine: the main job segmenting (`run --masks segment`), a
# binary before a change (.devpkg/base.xz: `strip -o B OLD && xz -c B > .devpkg/base.xz`) and the
# packed one after (tools/device/pack.sh), on 2 cores, on 2 cores with the GPU carver, and on all
# cores. Run there from the repository's root with .devpkg and .gl carried (see check.sh);
# everything lands in $OUT/results.tar.gz (docs/bench/gpu-h200-segment/ is its summary).
set -u
for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
mkdir -p /usr/share/fonts/truetype/dejavu && cp .devpkg/DejaVuSans.ttf /usr/share/fonts/truetype/dejavu/
mkdir -p /tmp/pkg && tar -C /tmp/pkg -xJf .devpkg/pkg.tar.xz
xz -dc .devpkg/base.xz > /tmp/pkg/hullcut-base && chmod +x /tmp/pkg/hullcut-base
export LD_LIBRARY_PATH=/tmp/pkg/lib
icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
[ -f $icd ] && export VK_DRIVER_FILES=$icd
R=/tmp/res; mkdir -p $R
{ nvidia-smi -L; nproc; lscpu | grep -E 'Model name'; } > $R/machine.txt 2>&1
/tmp/pkg/hullcut gpu-info > $R/gpu-info.txt 2>&1
two="taskset -c 0-1 env RAYON_NUM_THREADS=2"
for b in cur base; do
  H=/tmp/pkg/hullcut; [ $b = base ] && H=/tmp/pkg/hullcut-base
  s=$(date +%s); timeout 100 $two $H run --masks segment --rrd /tmp/s.rrd --report $R/seg2-$b.json > $R/seg2-$b.log 2>&1; echo "$b seg2 rc=$? $(( $(date +%s) - s )) s"
  s=$(date +%s); timeout 100 $two $H run --backend gpu --masks segment --rrd /tmp/s.rrd --report $R/gseg2-$b.json > $R/gseg2-$b.log 2>&1; echo "$b gseg2 rc=$? $(( $(date +%s) - s )) s"
  s=$(date +%s); timeout 100 $H run --masks segment --rrd /tmp/s.rrd --report $R/seg16-$b.json > $R/seg16-$b.log 2>&1; echo "$b seg16 rc=$? $(( $(date +%s) - s )) s"
done
tar -C /tmp -czf "$OUT/results.tar.gz" res
