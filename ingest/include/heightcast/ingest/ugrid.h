// heightcast/ingest/ugrid.h: quadtree simulation meshes (CF UGRID-1.0 map files, as SFINCS and other quadtree flood
// models write them) -> a grid with water steps, taken as they are: one cell per active face, no resampling
// (docs/design.md section 6).
//
// Read through GDAL's multidimensional API (GDALOpenEx with GDAL_OF_MULTIDIM_RASTER): the variable whose cf_role is
// mesh_topology with topology_dimension 2, its node_coordinates (x y), its face_node_connectivity (start_index, fill
// value), a face variable for the terrain (zb) and a face variable over time for the water level (zs), the time
// coordinate (CF units "seconds|minutes|hours|days since ..."), and the CRS (the variables' grid_mapping: crs_wkt or
// spatial_ref, or an EPSG code).
//
// The mesh must be a quadtree: every face a square of four nodes whose side is a power-of-two multiple of the
// smallest face's, all faces turned by one angle against the CRS's axes (the grid's rotation), each face's corner on
// the finest faces' lattice and aligned to its own size, no two faces overlapping. The lattice is fitted to every node
// by least squares (model.h): nodes stored as float32 lie within their rounding of it. Anything else is refused naming
// the face and what is wrong. Faces whose terrain is a fill value are holes; per step, faces whose level is a fill
// value, or not above the terrain, are dry (depth = level - terrain). Further face variables over time
// (Options::faceLayerVars: velocity magnitude, ...) become step layers of their own name and units, stored on the wet
// faces of each step (a fill value there is taken as 0, with a warning that counts them).
#pragma once

#include <string>

#include "heightcast/ingest/build.h"
#include "heightcast/ingest/ingest.h"

namespace hc::ingest {

// Whether `path` opens as a multidimensional dataset holding a 2D UGRID mesh topology (no error either way).
bool isUgridMesh(const std::string& path);

// The mesh of options.input into a grid file at `path` (atomically): terrain from options.terrainVar, water levels
// from options.waterSurfaceVar over every time step; the CRS from the file or options.sourceSrs. Fills `report`
// (description, CRS, method, warnings). Throws hc::Error naming the file and the problem; nothing is written then.
BuildSummary ingestUgridToFile(const Options& options, const std::string& path, LoadReport& report);

}  // namespace hc::ingest
