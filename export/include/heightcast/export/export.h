// heightcast/export/export.h: the smooth surface sampled on a regular raster and written for other
// tools: GeoTIFF (GIS: QGIS, gdalinfo), OpenEXR (float images) and OpenVDB (film and VFX tools).
//
// A sampled raster is north-up with square pixels of resolutionM, row 0 the northern-most; pixel
// (col, row) holds the surface at its centre. Undefined samples (holes, outside the grid, dry land
// for the water surface) are NaN here and are written as each format marks missing data. Every writer
// writes to a temporary file beside the target and renames it into place: no partial file survives.
//
// Georeference attributes (.exr header attributes, .vdb grid metadata; doubles, world = the grid's CRS [m]).
// One name, one meaning, in every heightcast file (hc-render's .exr frames too, render/image_io.h):
//   heightcast.gridOriginX/Y        the grid's origin, its domain's south-west corner: local = world - this
//                                   (.exr, .vdb)
//   heightcast.rasterNorthWestX/Y   the raster's north-west corner: the west edge of column 0, the north edge
//                                   of row 0 (.exr, whose row 0 is the top)
//   heightcast.rasterSouthWestX/Y   the raster's south-west corner: where voxel index space starts (.vdb)
//   heightcast.pixelSizeM           pixel side [m] (.exr; a .vdb has it as its voxel size)
// Strings: heightcast.crsWkt (the grid's CRS, "" = local metres) and heightcast.layer (.exr, .vdb),
// heightcast.units (.exr).
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "heightcast/grid/grid_file.h"
#include "heightcast/influence/surface.h"

namespace hc::exporting {

struct BoxWorld {
    double xMin, yMin, xMax, yMax;  // grid CRS [m]
};

struct SampledRaster {
    size_t width = 0, height = 0;
    double westWorld = 0, northWorld = 0;  // the raster's north-west corner, grid CRS [m]
    double pixelSizeM = 1;
    double originWorldX = 0, originWorldY = 0;  // the grid's origin (local frame = world - origin)
    std::string crsWkt;                         // "" = local metres
    std::string layer, units;                   // "elevation", "m"
    std::vector<float> values;                  // NaN = undefined
    std::vector<float> gradX, gradY;            // d value / d x, d y [units per m]; only if asked

    size_t definedCount() const;
};

// The raster that sampleSurface() would fill (geometry only, no values): checks the request first, so
// tools refuse it before any expensive work. Throws hc::Error as sampleSurface() does.
SampledRaster planRaster(const Grid& grid, double resolutionM, std::optional<BoxWorld> box,
                         size_t maxPixels = size_t{1} << 30);
// The same for a grid file not read whole: its shape and the bounds its summary stores.
SampledRaster planRaster(const GridFileInfo& file, double resolutionM, std::optional<BoxWorld> box,
                         size_t maxPixels = size_t{1} << 30);

// Samples `layer` over `box` (default: the grid's cells' extent) every resolutionM metres.
// Throws hc::Error for a non-positive resolution, an empty or inverted box, or a raster beyond
// maxPixels (it would not fit: the error says how many pixels it would be).
SampledRaster sampleSurface(const influence::SurfaceEvaluator& eval, const influence::Layer& layer,
                            const std::string& layerName, double resolutionM, std::optional<BoxWorld> box,
                            bool gradients, unsigned threads, bool progress, size_t maxPixels = size_t{1} << 30);

// The same out of core (docs/design.md section 4): the raster is sampled a tile of kExportTileCells^2 finest cells (at
// least a pixel) at a time, each from the cells whose kernels reach it, read from the file with their lists built on
// the spot (influence/region.h) and dropped: memory follows the tile and the raster, not the grid. The same bits as
// sampleSurface over the whole grid and its lists.
constexpr size_t kExportTileCells = 256;
SampledRaster sampleSurface(const GridRegionReader& file, const influence::KernelParams& params,
                            const influence::Layer& layer, const std::string& layerName, double resolutionM,
                            std::optional<BoxWorld> box, bool gradients, unsigned threads, bool progress,
                            size_t maxPixels = size_t{1} << 30);

// The grid file's cells as a UGRID-1.0 mesh (CF conventions) in NetCDF, as quadtree flood models such as SFINCS
// write their map files, through GDAL's multidimensional API (no other dependency): one square face per cell
// (mesh2d_face_nodes, counterclockwise from the south-west corner, start_index 0 or 1), its corners as shared nodes
// (mesh2d_node_x/y, world coordinates: a rotated grid gives a rotated mesh), the elevation as face variable zb, and
// for a grid with water every step's water level as zs(time, face) (zb + depth; _FillValue -99999 where dry), any
// further step layer likewise, and time [s]. The CRS as a CF grid_mapping variable "crs" (crs_wkt). hc-ingest reads
// it back as the same grid. The whole mesh is built in memory (about 60 bytes a cell and 8 per cell and step): a tool
// for meshes of simulation size, not for 100 M cells. Written to a temporary name and renamed. Throws hc::Error.
struct UgridOptions {
    int startIndex = 0;  // the connectivity's first node index (UGRID start_index): 0 or 1
};
struct UgridSummary {
    size_t nodes = 0, faces = 0, steps = 0;
    uint64_t wetFaces = 0;  // summed over the steps
};
UgridSummary writeUgrid(const std::string& gridPath, const std::string& path, const UgridOptions& options = {});

// GeoTIFF through GDAL: Float32, deflate, tiled; CRS and geotransform set; nodata -3.4028234663852886e+38
// (float32's lowest: below any elevation) where undefined.
void writeGeoTiff(const SampledRaster& raster, const std::string& path);

// OpenEXR (through hc::exr::writeFloatImage): one FLOAT channel named after the layer (NaN where undefined)
// and "A" (coverage: 1 defined, 0 undefined), ZIP compression. Header attributes (above):
// heightcast.gridOriginX/Y, heightcast.rasterNorthWestX/Y, heightcast.pixelSizeM, heightcast.crsWkt,
// heightcast.layer, heightcast.units.
void writeExr(const SampledRaster& raster, const std::string& path);

// OpenVDB: narrow-band level sets (FloatGrid, GRID_LEVEL_SET, half width 3 voxels, voxel = the
// raster's pixel): "terrain" from `terrain`, and "water_surface" from `water` where defined. Values
// are signed distances [m], negative below the surface, approximated by the vertical distance times
// the cosine of the slope. Index space: x east, y north, z up; voxel (i, j, k) at ((i + 0.5) v, (j + 0.5) v,
// k v) [m] from the raster's south-west corner horizontally and from elevation 0 vertically. Metadata
// (above): heightcast.gridOriginX/Y, heightcast.rasterSouthWestX/Y (that corner), heightcast.crsWkt,
// heightcast.layer.
// Throws hc::Error naming `path` in a build without OpenVDB (-DHC_WITH_VDB=OFF): as checkVdbAvailable().
void writeVdb(const SampledRaster& terrain, const SampledRaster* water, const std::string& path);
// Whether this build writes .vdb (CMake option HC_WITH_VDB).
bool vdbAvailable();
// Throws hc::Error naming `path` and how to get .vdb when this build has no OpenVDB; lets a tool refuse before any
// work.
void checkVdbAvailable(const std::string& path);

}  // namespace hc::exporting
