#!/usr/bin/env bash
# Enforces DESIGN.md's dependency rules with `cargo tree` (normal and build edges, as shipped):
#   - only hullcut-viz and the binary (and the test crate) reach rerun;
#   - only hullcut-calib, hullcut-capture and the binary (and the test crate) reach OpenCV, and
#     hullcut-pipeline only through hullcut-capture (never directly);
#   - only hullcut-gpu, the binary and the test crate reach wgpu with all features; hullcut-hull
#     and hullcut-sim (and hullcut-pipeline) reach it only through their `gpu` feature.
# Exits non-zero, naming the crate and the path to the forbidden dependency, when a rule breaks.
set -euo pipefail
cd "$(dirname "$0")/.."

fail=0
crates=()
for manifest in crates/*/Cargo.toml; do
    crates+=("$(sed -n 's/^name = "\(.*\)"/\1/p' "$manifest" | head -n 1)")
done

allowed() { # allowed CRATE LIST...
    local c=$1; shift
    for a in "$@"; do [ "$c" = "$a" ] && return 0; done
    return 1
}

reaches() { # reaches CRATE DEP [cargo tree flags...]: prints the inverted path when CRATE depends on DEP
    local crate=$1 dep=$2; shift 2
    local out err rc=0
    err=$(mktemp)
    out=$(cargo tree --offline -q -p "$crate" -e normal,build "$@" -i "$dep" 2>"$err") || rc=$?
    if [ "$rc" -ne 0 ] && ! grep -q "did not match any packages" "$err"; then
        echo "check-deps: cargo tree failed for $crate:" >&2
        cat "$err" >&2
        rm -f "$err"
        exit 2
    fi
    rm -f "$err"
    printf '%s' "$out" | head -n 12
}

# The mechanism must see a dependency that is there, or every check below would pass vacuously.
if [ -z "$(reaches hullcut-viz rerun)" ]; then
    echo "check-deps: cargo tree does not show hullcut-viz -> rerun; the checker is broken" >&2
    exit 2
fi

check() { # check CRATE DEP FLAGS...
    local crate=$1 dep=$2; shift 2
    local path
    path=$(reaches "$crate" "$dep" "$@")
    if [ -n "$path" ]; then
        echo "check-deps: $crate must not depend on $dep ($*):"
        echo "$path" | sed 's/^/    /'
        fail=1
    fi
}

for c in "${crates[@]}"; do
    allowed "$c" hullcut-viz hullcut || check "$c" rerun --all-features
    allowed "$c" hullcut-calib hullcut-capture hullcut hullcut-pipeline || check "$c" opencv --all-features
    case "$c" in
        hullcut-gpu | hullcut) ;;
        hullcut-hull | hullcut-sim | hullcut-pipeline) check "$c" wgpu --no-default-features ;;
        *) check "$c" wgpu --all-features ;;
    esac
done

# The pipeline reaches OpenCV through hullcut-capture alone.
if cargo tree --offline -q -p hullcut-pipeline -e normal --all-features --depth 1 | grep -q ' opencv '; then
    echo "check-deps: hullcut-pipeline depends on opencv directly (it must go through hullcut-capture)"
    fail=1
fi

if [ "$fail" -ne 0 ]; then
    echo "check-deps: dependency rules broken (see DESIGN.md, 'Dependency rules')"
    exit 1
fi
echo "check-deps: ${#crates[@]} crates follow the dependency rules (${crates[*]})"
