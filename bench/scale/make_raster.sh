#!/usr/bin/env bash
# bench/scale/make_raster.sh OUT.tif [SIDE_PX]: a SIDE_PX x SIDE_PX (default 10240: 104.9 M pixels) real-terrain
# raster for the issue-13 scale benchmarks (bench/scale/run.sh), made with GDAL's command-line tools only.
#
# Source: /work/shared/data/south_glacier_utm7.tif (override with HC_SCALE_SOURCE): South Glacier, St Elias
# Mountains, Yukon; a 20 m glacier DEM (1685-3165 m) in WGS 84 / UTM zone 7N (EPSG:32607), 248 x 300 pixels, 100 %
# valid (nodata -9999 declared, none present). Chosen because it is the only raster in /work/shared/data that is in a
# projected CRS with an EPSG identity, in metres, at 10-30 m and without nodata, so every output pixel is valid
# (kilauea_utm.nc, 30 m, has 3 % nodata ocean and a CRS without identity; the 1 m LiDAR has 31 m of relief).
# Another source (HC_SCALE_SOURCE) keeps its own CRS and pixel size: a geographic mosaic of the two SRTM tiles
# (gdalbuildvrt of N00E010.hgt and N00E011.hgt) makes the geographic raster of the MPI benchmark (docs/benchmarks.md).
#
# Mirroring keeps the terrain continuous: the source A and its mirror images (flipped in x, in y, in both) make a
# 2 x 2 block M = [A fx(A); fy(A) fxy(A)] whose opposite edges match, so copies of M side by side are continuous
# (every seam is a mirror line). Blocks double (4 copies of the last block) until they cover SIDE_PX, then the
# output is the north-west SIDE_PX x SIDE_PX window. The mirror images are made by giving A a geotransform with
# a negative pixel size (gdal_translate -a_ullr) and warping it back onto A's own grid with nearest neighbour:
# an exact flip. The output keeps A's CRS, 20 m pixels and north-west corner (the mosaic extends east and south),
# Float32 (the source's Float64 heights are given to the mm; Float32 keeps 0.25 mm at 3165 m), the source's nodata,
# tiled 256 x 256, uncompressed. Deterministic (no timestamps, fixed inputs) and idempotent: the output is written
# under a temporary name and renamed, and a rerun writes the same bytes.
set -euo pipefail

usage() { echo "usage: $0 OUT.tif [SIDE_PX (default 10240)]" >&2; exit 2; }
[[ $# -ge 1 && $# -le 2 ]] || usage
out=$1
side=${2:-10240}
[[ $side =~ ^[0-9]+$ && $side -ge 1 ]] || { echo "make_raster.sh: error: SIDE_PX '$side': not a positive integer" >&2; exit 2; }
src=${HC_SCALE_SOURCE:-/work/shared/data/south_glacier_utm7.tif}
[[ -r $src ]] || { echo "make_raster.sh: error: $src: cannot read" >&2; exit 1; }

# OUT.vrt: no 420 MB GeoTIFF but a VRT over the four small mirror images (1.2 MB in all) kept in OUT.parts/ beside
# it, with relative paths: the same pixels, for carrying to another machine (bench/gpu/pack.sh).
if [[ $out == *.vrt ]]; then
    work=$out.parts
    rm -rf "$work" && mkdir -p "$work"
else
    work=$(mktemp -d "${TMPDIR:-/tmp}/make_raster.XXXXXX")
    trap 'rm -rf "$work"' EXIT
fi
export GDAL_PAM_ENABLED=NO  # no .aux.xml side files
q=(-q)

# The source's size and corners (from gdalinfo's JSON; jq-free: python3 is on every Debian with GDAL's tools).
# Its nodata value is kept: the mirror images carry it (gdalwarp keeps a source's nodata), and the output declares it,
# -9999 where the source declares none. (Declaring -9999 over a source whose nodata was another value, as this script
# did, made Kilauea's -32768 ocean pixels valid elevations.)
read -r w h x0 y0 px py nodata < <(gdalinfo -json "$src" | python3 -c '
import json, sys
j = json.load(sys.stdin); g = j["geoTransform"]; nd = j["bands"][0].get("noDataValue")
print(j["size"][0], j["size"][1], repr(g[0]), repr(g[3]), repr(g[1]), repr(g[5]), "-9999" if nd is None else repr(nd))')
read -r x1 y1 < <(python3 -c "print(repr($x0 + $w * $px), repr($y0 + $h * $py))")

# A as Float32, and its three mirror images on A's own grid.
gdal_translate "${q[@]}" -ot Float32 "$src" "$work/a.tif"
flip() {  # flip NAME ULX ULY LRX LRY: A with corners swapped, warped back onto A's grid
    gdal_translate "${q[@]}" -of VRT -a_ullr "$2" "$3" "$4" "$5" "$work/a.tif" "$work/$1_geo.vrt"
    gdalwarp "${q[@]}" -r near -te "$x0" "$y1" "$x1" "$y0" -ts "$w" "$h" "$work/$1_geo.vrt" "$work/$1.tif"
}
flip fx "$x1" "$y0" "$x0" "$y1"
flip fy "$x0" "$y1" "$x1" "$y0"
flip fxy "$x1" "$y1" "$x0" "$y0"

# place SRC DST COL ROW BW BH: SRC (BW x BH px) as a VRT whose north-west corner is (COL, ROW) pixels from A's.
place() {
    local ulx uly lrx lry
    read -r ulx uly lrx lry < <(python3 -c "print(repr($x0 + $3 * $px), repr($y0 + $4 * $py), repr($x0 + ($3 + $5) * $px), repr($y0 + ($4 + $6) * $py))")
    gdal_translate "${q[@]}" -of VRT -a_ullr "$ulx" "$uly" "$lrx" "$lry" "$1" "$2"
}
place "$work/a.tif" "$work/m_0.vrt" 0 0 "$w" "$h"
place "$work/fx.tif" "$work/m_1.vrt" "$w" 0 "$w" "$h"
place "$work/fy.tif" "$work/m_2.vrt" 0 "$h" "$w" "$h"
place "$work/fxy.tif" "$work/m_3.vrt" "$w" "$h" "$w" "$h"
gdalbuildvrt "${q[@]}" "$work/b0.vrt" "$work"/m_[0-3].vrt
bw=$((2 * w)) bh=$((2 * h)) k=0
while ((bw < side || bh < side)); do
    place "$work/b$k.vrt" "$work/c${k}_0.vrt" 0 0 "$bw" "$bh"
    place "$work/b$k.vrt" "$work/c${k}_1.vrt" "$bw" 0 "$bw" "$bh"
    place "$work/b$k.vrt" "$work/c${k}_2.vrt" 0 "$bh" "$bw" "$bh"
    place "$work/b$k.vrt" "$work/c${k}_3.vrt" "$bw" "$bh" "$bw" "$bh"
    gdalbuildvrt "${q[@]}" "$work/b$((k + 1)).vrt" "$work/c${k}"_[0-3].vrt
    k=$((k + 1)) bw=$((2 * bw)) bh=$((2 * bh))
done

if [[ $out == *.vrt ]]; then
    tmp="$work/out.tmp.$$.vrt"
    gdal_translate "${q[@]}" -of VRT -srcwin 0 0 "$side" "$side" -a_nodata "$nodata" "$work/b$k.vrt" "$tmp"
    sed 's#relativeToVRT="1">#relativeToVRT="1">'"$(basename "$work")"'/#' "$tmp" > "$out.tmp.$$" && rm -f "$tmp"
    mv -f "$out.tmp.$$" "$out"
    echo "$out: ${side} x ${side} px, a VRT over $(basename "$work")/"
    exit 0
fi
tmp="$out.tmp.$$.tif"
gdal_translate "${q[@]}" -srcwin 0 0 "$side" "$side" -a_nodata "$nodata" \
    -co TILED=YES -co BLOCKXSIZE=256 -co BLOCKYSIZE=256 -co COMPRESS=NONE -co BIGTIFF=IF_SAFER \
    "$work/b$k.vrt" "$tmp"
mv -f "$tmp" "$out"
echo "$out: ${side} x ${side} px ($(python3 -c "print(f'{$side * $side / 1e6:.1f}')") M), pixels of $px x ${py#-} (the source's CRS units), from $(basename "$src") mirrored"
