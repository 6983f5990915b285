#!/usr/bin/env python3
"""Copies the shared libraries a binary loads into one folder, for a machine that lacks them.

Usage: stub-libs.py BINARY OUTDIR

Heavy libraries that OpenCV links but hullcut never calls (GDAL, FFmpeg, GStreamer, libgphoto2,
libdc1394, ...) are replaced by stand-ins built with clang: each defines, under the same soname
and symbol versions, the symbols the kept objects reference, and a called stand-in prints its
name on stderr and returns 0 (OpenCV registers GDAL's drivers at start-up, for one). glibc and
libstdc++ are left to the machine. Prints what it kept and stood in for."""
import os, re, subprocess, sys, collections

binary, outdir = sys.argv[1], sys.argv[2]
STUB = re.compile(r"lib(gdal|gdcm|av(codec|format|util|device|filter)|sw(scale|resample)|gst|glib|gobject|gio|gmodule|dc1394|gphoto2|GLX|GL\.|raw1394|usb|vtk|hdf5|spatialite|proj|geos|poppler|curl|xml2|kml|netcdf|arrow|parquet|odbc|qhull|heif|cfitsio|tesseract|openblas)")
SKIP = re.compile(r"^(libc\.so|libm\.so|libdl\.so|libpthread|librt\.so|ld-linux|libstdc\+\+|libgcc_s)")

def needed(path):
    out = subprocess.run(["readelf", "-d", path], capture_output=True, text=True).stdout
    return re.findall(r"\(NEEDED\)\s+Shared library: \[(.+?)\]", out)

resolved = {}
for line in subprocess.run(["ldd", binary], capture_output=True, text=True).stdout.splitlines():
    m = re.match(r"\s*(\S+) => (\S+)", line)
    if m: resolved[m.group(1)] = m.group(2)

def resolve(name):
    if name not in resolved:
        for d in ["/usr/lib/x86_64-linux-gnu", "/lib/x86_64-linux-gnu", "/usr/lib/x86_64-linux-gnu/blas", "/usr/lib/x86_64-linux-gnu/lapack"]:
            p = os.path.join(d, name)
            if os.path.exists(p): resolved[name] = p; break
    return resolved.get(name)

kept, stubs, queue = {}, set(), collections.deque(needed(binary))
while queue:
    n = queue.popleft()
    if n in kept or n in stubs or SKIP.match(n): continue
    if STUB.match(n): stubs.add(n); continue
    p = resolve(n)
    if p is None: print("unresolved", n); continue
    kept[n] = p
    queue.extend(needed(p))

def dynsyms(path):
    out = subprocess.run(["readelf", "--dyn-syms", "-W", path], capture_output=True, text=True).stdout
    for line in out.splitlines():
        f = line.split()
        if len(f) >= 8 and f[0].endswith(":") and f[0][:-1].isdigit():
            yield f  # num value size type bind vis ndx name

undef = collections.defaultdict(set)  # name -> versions referenced
for p in [binary] + list(kept.values()):
    for f in dynsyms(p):
        if f[6] == "UND" and f[4] in ("GLOBAL",):
            name = f[7]; ver = None
            if "@" in name: name, ver = name.split("@", 1); ver = ver.split(" ")[0].lstrip("@")
            undef[name].add(ver)

os.makedirs(outdir, exist_ok=True)
total = 0
for n, p in kept.items():
    real = os.path.realpath(p)
    subprocess.run(["cp", real, os.path.join(outdir, n)], check=True)
    total += os.path.getsize(real)
for n in sorted(stubs):
    p = resolve(n)
    funcs, objs, versions = [], [], collections.defaultdict(list)
    for f in dynsyms(p):
        if f[6] == "UND": continue
        name = f[7]; ver = None
        if "@" in name: name, ver = re.split(r"@+", name, 1); ver = ver.split(" ")[0]
        if name not in undef or f[3] not in ("FUNC", "OBJECT", "IFUNC"): continue
        if f[3] == "OBJECT": objs.append((name, int(f[2], 0) if f[2].startswith("0x") else int(f[2])))
        else: funcs.append(name)
        if ver: versions[ver].append(name)
    c = ['#include <stdio.h>', '#include <stdlib.h>', 'static void die(const char *n) { fprintf(stderr, "stub %s called (%s), returns 0\\n", n, "' + n + '"); }']
    for i, s in enumerate(funcs):
        c.append(f'long f{i}(void) __asm__("{s}"); long f{i}(void) {{ die("{s}"); return 0; }}')
    for i, (s, size) in enumerate(objs):
        c.append(f'char o{i}[{max(size,8)}] __asm__("{s}") __attribute__((aligned(64))) = {{0}};')
    src = os.path.join(outdir, n + ".c"); open(src, "w").write("\n".join(c) + "\n")
    cmd = ["clang", "-shared", "-fPIC", "-O0", "-o", os.path.join(outdir, n), src, f"-Wl,-soname,{n}"]
    if versions:
        vs = os.path.join(outdir, n + ".map")
        open(vs, "w").write("".join(f"{v} {{ global: {' '.join(s + ';' for s in syms)} }};\n" for v, syms in versions.items()) + "")
        cmd.append(f"-Wl,--version-script={vs}")
    subprocess.run(cmd, check=True)
    os.remove(src)
    if versions: os.remove(vs)
    print(f"stub {n}: {len(funcs)} functions, {len(objs)} objects")
print(f"kept {len(kept)} libraries, {total/1e6:.1f} MB; stubs {len(stubs)}")
