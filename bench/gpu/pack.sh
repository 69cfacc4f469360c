#!/usr/bin/env bash
# bench/gpu/pack.sh [KIT_DIR]: packs the built tools, the shared libraries they load and the 105 M-cell benchmark
# raster (as a VRT over four small GeoTIFFs, bench/scale/make_raster.sh) into KIT_DIR (default .devkit, ignored by
# git), for a machine with a GPU that has none of the toolkit's Debian packages and cannot install them: the
# machine lent to a session by this workplace's device tool (docs/benchmarks.md, "GL backend on a GPU"). There
# bench/gpu/on_device.sh KIT_DIR runs the benchmarks. On a machine with the packages, build and run there instead.
#
# Carried: every library the tools load but the C and C++ runtimes (glibc, libstdc++, libgcc_s; the target's own,
# newer ones serve), xz-compressed. glvnd's libEGL/libOpenGL are carried too; the GPU's own EGL driver is the
# target's (NVIDIA's, through glvnd's vendor files). A default build is tuned with -march=native (HC_NATIVE): the
# target's CPU must then have every instruction set extension of this machine's. Where it may not (this machine has
# AVX-512 subsets the lent Xeons need not), pack a build made for it: bash scripts/build.sh DIR -DHC_NATIVE=OFF
# -DCMAKE_CXX_FLAGS=-march=x86-64-v3 -DHC_BUILD_TESTS=OFF, then HC_BIN=DIR/bin bash bench/gpu/pack.sh.
set -euo pipefail
here=$(cd "$(dirname "$0")/../.." && pwd)
kit=${1:-$here/.devkit}
bin=${HC_BIN:-$here/build/bin}
tools=(hc-ingest hc-info hc-influence hc-probe hc-render hc-view hc-bench hc-bench-parallel)
for t in "${tools[@]}"; do [[ -x $bin/$t ]] || { echo "pack.sh: error: $bin/$t: not built (bash scripts/build.sh)" >&2; exit 1; }; done
for p in gdalinfo /usr/bin/time xz python3; do command -v "$p" > /dev/null || { echo "pack.sh: error: $p: not installed" >&2; exit 1; }; done

rm -rf "$kit" && mkdir -p "$kit/bin" "$kit/stage/lib"
for t in "${tools[@]}"; do cp "$bin/$t" "$kit/stage/"; done
cp "$(command -v gdalinfo)" /usr/bin/time "$kit/stage/"
# HC_GPU_BEFORE=PATH: another build of hc-render (an earlier commit's) packed as hc-render-before, to time both on
# the same machine (on_device.sh's fly part alternates them).
[[ -n ${HC_GPU_BEFORE:-} ]] && cp "$HC_GPU_BEFORE" "$kit/stage/hc-render-before"
# HC_GPU_AB="LABEL=BINDIR ...": earlier builds' hc-bench and hc-render (those BINDIR has), packed as hc-bench-LABEL and
# hc-render-LABEL, for on_device.sh's ab part.
for ab in ${HC_GPU_AB:-}; do
    label=${ab%%=*} dir=${ab#*=}
    [[ $label =~ ^[A-Za-z0-9_]+$ && -d $dir ]] || { echo "pack.sh: error: HC_GPU_AB: $ab: expected LABEL=BINDIR" >&2; exit 1; }
    for t in hc-bench hc-render; do [[ -x $dir/$t ]] && cp "$dir/$t" "$kit/stage/$t-$label"; done
done
strip "$kit"/stage/hc-* 2>/dev/null || true
# The libraries: every one ldd resolves for the tools, but the C and C++ runtimes.
for f in "$kit"/stage/*; do [[ -f $f ]] && ldd "$f"; done | awk '/=> \// { print $3 }' | sort -u |
    grep -v -E '/(libc|libm|libpthread|libdl|librt|libstdc\+\+|libgcc_s|ld-linux-x86-64)\.so' |
    while read -r lib; do cp -L "$lib" "$kit/stage/lib/"; done
tar -C "$kit/stage" -cf - . | xz -T0 -6 > "$kit/bin/kit.tar.xz"
rm -rf "$kit/stage"
# The raster of bench/scale/run.sh's 105 M-cell column, 1.2 MB instead of 420 MB (HC_GPU_SIDE: another side in px).
side=${HC_GPU_SIDE:-10240}
bash "$here/bench/scale/make_raster.sh" "$kit/raster/dem$side.vrt" "$side"
du -sh "$kit"
