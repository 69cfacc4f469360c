#!/usr/bin/env bash
# bench/gpu/on_device.sh KIT_DIR OUT_DIR: on a machine with a GPU, runs the GPU benchmarks of docs/benchmarks.md with the
# tools bench/gpu/pack.sh packed into KIT_DIR, and writes the logs to OUT_DIR. Parts (HC_GPU_PARTS, default all,
# comma-separated):
#   scale   bench/scale/run.sh on the kit's raster, 105 M cells (every tool from a cold page cache; the GL row on the GPU)
#   fly     hc-render --fly on that grid: flights of 1920x1080 frames on the GL backend (texels kept, and every
#           frame from scratch; each frame read back and written, and back to back with --fly-last-image) and on the
#           CPU backend, from the look-at camera and the overview
#   report  hc-bench --backend gl on the report's four scenes, in memory and out of core from the pyramid, each with
#           a fly-through of 20 frames (texels kept against every frame afresh)
#   beams   the GL walk with and without its beams (--beam-tile 4 and 0): the look-at flight back to back, alternated twice
#   grid    only the scale part's grid and pyramid (hc-ingest, hc-influence --no-lists), unmeasured, for the ab part
#   ab      the earlier builds pack.sh packed (HC_GPU_AB) against this one, alternated twice: hc-bench --backend gl in memory
#           on Petzenkirchen and Wachau with a fly-through, and (after the scale or grid part) the look-at flight back to
#           back, with texels kept and from scratch (an hc-render older than b892aa2 has no --fly-last-image and fails
#           those flights, saying so)
#   same    (after the scale or grid part) the earlier builds' hc-render (HC_GPU_AB) against this one's: the look-at
#           flight from scratch (3 frames, PNG and EXR) and moving (6 frames, PNG), each file compared byte for byte
#   view    (after the scale or grid part) hc-view offscreen on the GPU (no display needed: a framebuffer in an EGL
#           context): 600 (HC_GPU_VIEW_FRAMES) scripted frames at 1920x1080 flying to the look-at view and to the
#           overview, vsync off; the frame rate, median and 99th percentile frame, and the last frame's screenshot
#   pool    hc-bench-parallel on the machine's cores: what a parallelFor call costs beyond its work (a fresh frame makes
#           a dozen), back to back and after pauses
set -uo pipefail
[[ $# -eq 2 ]] || { echo "usage: $0 KIT_DIR OUT_DIR" >&2; exit 2; }
kit=$(cd "$1" && pwd) out=$2
here=$(cd "$(dirname "$0")/../.." && pwd)
parts=,${HC_GPU_PARTS:-scale,fly,report,beams},
mkdir -p "$out"
root=${TMPDIR:-/tmp}/hc-kit
rm -rf "$root" && mkdir -p "$root"
xz -dc "$kit/bin/kit.tar.xz" | tar -C "$root" -xf -
export PATH=$root:$PATH LD_LIBRARY_PATH=$root/lib
# glvnd finds NVIDIA's EGL driver through its vendor file; on the lent machines that lies under /usr/local/nvidia.
for f in /usr/share/glvnd/egl_vendor.d/10_nvidia.json /usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json; do
    [[ -r $f ]] && { export __EGL_VENDOR_LIBRARY_FILENAMES=$f; break; }
done
{
    date -u
    nvidia-smi -L 2>&1
    nvidia-smi --query-gpu=driver_version,clocks.max.sm,memory.total --format=csv 2>&1
    echo "cpus: $(nproc) x $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2)"
    free -g | head -2
    hc-render --help > /dev/null && echo "tools run"
} 2>&1 | tee "$out/machine.txt"

work=${TMPDIR:-/tmp}/hc-scale
rasters=("$kit"/raster/dem*.vrt)
raster=${rasters[0]}
# The flights' camera (HC_GPU_LOOK_AT: another, inside a smaller raster of pack.sh's HC_GPU_SIDE).
look=(--look-at "${HC_GPU_LOOK_AT:-700000,6640000,4200,710000,6650000,2600}")
if [[ $parts == *,scale,* ]]; then
    # No address-space cap: the GPU driver reserves far more address space than it uses (peak RSS is the figure).
    HC_BIN=$root HC_SCALE_COLD=1 HC_SCALE_CAP_MIB=${HC_SCALE_CAP_MIB:-400000} bash "$here/bench/scale/run.sh" "$raster" "$work" \
        > "$out/scale.txt" 2>&1
    tail -n 30 "$out/scale.txt"
    for f in "$work"/*.log; do echo "== $f"; cat "$f"; done > "$out/scale_logs.txt"
fi
if [[ $parts == *,fly,* ]]; then
    [[ -r $work/grid.hcg ]] || { echo "on_device.sh: fly: $work/grid.hcg missing (run the scale part first)" >&2; exit 1; }
    mkdir -p "$work/fly"
    # The GPU's clock every 200 ms while the flights run (a GPU idle between frames lowers it).
    nvidia-smi --query-gpu=timestamp,clocks.sm,utilization.gpu --format=csv -lms 200 > "$out/fly_clocks.csv" 2>&1 &
    clocks=$!
    {
        # An earlier build packed beside it (pack.sh's HC_GPU_BEFORE): its GL flight and this one's, alternated twice.
        if [[ -x $root/hc-render-before ]]; then
            for round in 1 2; do
                for r in hc-render-before hc-render; do
                    echo "== $r, round $round"
                    $r "$work/grid.hcg" -o "$work/fly/ab.png" --size 1920x1080 --backend gl "${look[@]}" --fly 40 --fly-step 20
                done
            done
        fi
        for backend in gl cpu; do
            echo "== $backend, every frame read back and written"
            hc-render "$work/grid.hcg" -o "$work/fly/$backend.png" --size 1920x1080 --backend $backend "${look[@]}" --fly 40 --fly-step 20
            hc-render "$work/grid.hcg" -o "$work/fly/$backend.png" --size 1920x1080 --backend $backend "${look[@]}" --fly 10 --fly-step 20 --fly-fresh
        done
        # Back to back as the viewer draws (--fly-last-image: nothing read back or written between frames, so the GPU
        # does not idle and lower its clock): 200 frames with texels kept (4 km), then 20 from scratch.
        echo "== gl, back to back"
        hc-render "$work/grid.hcg" -o "$work/fly/b2b.png" --size 1920x1080 --backend gl "${look[@]}" --fly 200 --fly-step 20 --fly-last-image
        hc-render "$work/grid.hcg" -o "$work/fly/b2b.png" --size 1920x1080 --backend gl "${look[@]}" --fly 20 --fly-step 20 --fly-fresh --fly-last-image
        hc-render "$work/grid.hcg" -o "$work/fly/over.png" --size 1920x1080 --backend gl --fly 20 --fly-step 50
    } > "$out/fly.txt" 2>&1
    kill $clocks 2>/dev/null
    cp "$work/fly/gl_0009.png" "$out/fly_gl_0009.png" 2>/dev/null
    grep -E "^== |backend|frames 1\.\." "$out/fly.txt"
fi
if [[ $parts == *,beams,* ]]; then
    [[ -r $work/grid.hcg ]] || { echo "on_device.sh: beams: $work/grid.hcg missing (run the scale part first)" >&2; exit 1; }
    mkdir -p "$work/beams"
    {
        for round in 1 2; do
            for tile in 0 4; do
                echo "== --beam-tile $tile, round $round"
                hc-render "$work/grid.hcg" -o "$work/beams/b.png" --size 1920x1080 --backend gl "${look[@]}" --fly 40 --fly-step 20 \
                    --beam-tile $tile --fly-last-image
            done
        done
    } > "$out/beams.txt" 2>&1
    grep -E "^== |frames 1\.\." "$out/beams.txt"
fi
if [[ $parts == *,grid,* && ! -r $work/grid.hcg ]]; then
    # The scale part's grid and pyramid without its measurements (for the ab part alone).
    mkdir -p "$work"
    hc-ingest "$raster" -o "$work/grid.hcg" --quiet && hc-influence "$work/grid.hcg" --no-lists -p "$work/grid.hcp" --quiet ||
        { echo "on_device.sh: grid: building $work/grid.hcg failed" >&2; exit 1; }
fi
if [[ $parts == *,ab,* ]]; then
    labels=()
    for f in "$root"/hc-bench-* "$root"/hc-render-*; do
        [[ -x $f && $f != */hc-render-before && $f != */hc-bench-parallel ]] || continue
        l=${f##*/hc-bench-} && l=${l##*/hc-render-}
        [[ " ${labels[*]} " == *" $l "* ]] || labels+=("$l")
    done
    ((${#labels[@]})) || { echo "on_device.sh: ab: no earlier build in the kit (pack.sh's HC_GPU_AB)" >&2; exit 1; }
    labels+=(this)
    name() { [[ $2 == this ]] && echo "$1" || echo "$1-$2"; }
    earlierBench=0
    for l in "${labels[@]}"; do [[ $l != this && -x $root/hc-bench-$l ]] && earlierBench=1; done
    if ((earlierBench)); then  # an earlier hc-bench to compare with
        for round in 1 2; do
            for l in "${labels[@]}"; do
                b=$(name hc-bench "$l")
                [[ -x $root/$b ]] || continue
                echo "== $b, round $round"
                $b --backend gl --scenarios Petzenkirchen,Wachau --repeat 10 --fly-frames 20 --fly-step 10
            done
        done > "$out/ab_bench.txt" 2>&1
        grep -E "^== |total .*GPU|^(Petzenkirchen|Wachau) +[0-9.]+ +[0-9.]+ +[0-9.]+ +[0-9.]+ +[0-9.]+ +[0-9.]+ +[0-9]+ +[0-9]+$" "$out/ab_bench.txt"
    fi
    if [[ -r $work/grid.hcg ]]; then
        for round in 1 2; do
            for l in "${labels[@]}"; do
                r=$(name hc-render "$l")
                [[ -x $root/$r ]] || continue
                echo "== $r, texels kept, round $round"
                $r "$work/grid.hcg" -o "$work/ab.png" --size 1920x1080 --backend gl "${look[@]}" --fly 200 --fly-step 20 --fly-last-image
                echo "== $r, from scratch, round $round"
                $r "$work/grid.hcg" -o "$work/ab.png" --size 1920x1080 --backend gl "${look[@]}" --fly 20 --fly-step 20 --fly-last-image --fly-fresh
            done
        done > "$out/ab_fly.txt" 2>&1
        grep -E "^== |frames 1\.\." "$out/ab_fly.txt"
    fi
fi
if [[ $parts == *,same,* ]]; then
    [[ -r $work/grid.hcg ]] || { echo "on_device.sh: same: $work/grid.hcg missing (run the scale or grid part first)" >&2; exit 1; }
    mkdir -p "$work/same"
    {
        for f in "$root"/hc-render-*; do
            [[ -x $f && $f != */hc-render-before ]] || continue
            l=${f##*/hc-render-}
            for r in "hc-render-$l" hc-render; do
                $r "$work/grid.hcg" -o "$work/same/$r.png" --exr "$work/same/$r.exr" --size 1920x1080 --backend gl "${look[@]}" \
                    --fly 3 --fly-step 20 --fly-fresh > /dev/null
                $r "$work/grid.hcg" -o "$work/same/$r-kept.png" --size 1920x1080 --backend gl "${look[@]}" --fly 6 --fly-step 20 > /dev/null
            done
            for k in 0000 0001 0002; do
                for e in png exr; do
                    cmp -s "$work/same/hc-render-${l}_$k.$e" "$work/same/hc-render_$k.$e" && v="the same bytes" || v=DIFFERENT
                    echo "$l against this, from scratch, frame $k $e: $v"
                done
            done
            for k in 0000 0003 0005; do
                cmp -s "$work/same/hc-render-$l-kept_$k.png" "$work/same/hc-render-kept_$k.png" && v="the same bytes" || v=DIFFERENT
                echo "$l against this, moving, frame $k png: $v"
            done
        done
    } > "$out/same.txt" 2>&1
    cat "$out/same.txt"
fi
if [[ $parts == *,view,* ]]; then
    [[ -r $work/grid.hcg ]] || { echo "on_device.sh: view: $work/grid.hcg missing (run the scale or grid part first)" >&2; exit 1; }
    n=${HC_GPU_VIEW_FRAMES:-600}
    {
        for round in 1 2; do
            echo "== look-at, round $round"
            hc-view "$work/grid.hcg" --offscreen --backend gl --size 1920x1080 "${look[@]}" --frames "$n" --screenshot "$out/view_look.png"
            echo "== overview, round $round"
            hc-view "$work/grid.hcg" --offscreen --backend gl --size 1920x1080 --frames "$n" --screenshot "$out/view_over.png"
        done
    } > "$out/view.txt" 2>&1
    grep -E "^== |backend|^frames:|error" "$out/view.txt"
fi
if [[ $parts == *,pool,* ]]; then
    hc-bench-parallel --threads "$(nproc),$(($(nproc) / 2)),2" > "$out/pool.txt" 2>&1
    cat "$out/pool.txt"
fi
if [[ $parts == *,report,* ]]; then
    {
        hc-bench --backend gl --repeat 10 --fly-frames 20 --fly-step 10 --json "$out/report_gl.json"
        hc-bench --backend gl --repeat 10 --out-of-core --pyramid --fly-frames 20 --fly-step 10 --json "$out/report_gl_ooc.json"
    } > "$out/report.txt" 2>&1
    grep -E -A6 "^scenario|^incremental" "$out/report.txt"
fi
