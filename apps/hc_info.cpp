// hc-info: header and statistics of a grid file (from its META, or --verify: the whole file checked); JSON and
// per-cell CSV export.
#include <array>
#include <cinttypes>
#include <cstdio>
#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>
#include <proj.h>

#include "heightcast/support/cli.h"
#include "heightcast/core/atomic_file.h"
#include "heightcast/core/error.h"
#include "heightcast/grid/grid_file.h"

namespace {

struct Summary {
    double minCell = 0, maxCell = 0;
    std::array<double, 4> extent{};  // world xmin, ymin, xmax, ymax
};

Summary summarise(const hc::GridFileInfo& info) {
    const hc::Grid& g = info.shape;
    const auto& perLevel = info.summary.cellsPerLevel;
    Summary s;
    int lo = -1, hi = -1;
    for (size_t l = 0; l < perLevel.size(); ++l)
        if (perLevel[l]) {
            if (lo < 0) lo = int(l);
            hi = int(l);
        }
    if (lo >= 0) {
        s.minCell = g.levelSizeM(lo);
        s.maxCell = g.levelSizeM(hi);
    }
    // Finest units to world metres as Grid::boundsLocal computes the edges (integer times the cell size); a rotated
    // grid's extent is the box around its rotated bounds.
    const auto& b = info.summary.boundsFinest;
    s.extent = {HUGE_VAL, HUGE_VAL, -HUGE_VAL, -HUGE_VAL};
    for (int corner = 0; corner < 4; ++corner) {
        double x = 0, y = 0;
        g.localToWorld(double(b[corner & 1 ? 2 : 0]) * g.finestCellM, double(b[corner & 2 ? 3 : 1]) * g.finestCellM, x,
                       y);
        s.extent = {std::min(s.extent[0], x), std::min(s.extent[1], y), std::max(s.extent[2], x),
                    std::max(s.extent[3], y)};
    }
    return s;
}

// What was checked, in one line: a summary must not claim a check it did not make.
std::string checkedLine(const hc::GridFileInfo& info) {
    if (!info.verified)
        return "header, section table and META checked; cells and values NOT verified (hc-info --verify checks them)";
    if (info.fileMinor < 2)
        return "valid (every checksum, every cell invariant and both hashes checked; format 1." +
               std::to_string(info.fileMinor) + " stores no summary: read in full)";
    return "valid (every checksum by " + std::to_string(info.blockBytes >> 10) +
           " KiB block, every cell invariant, both hashes and the stored summary checked)";
}

// The grid CRS's name: as ingest stored it (format 1.1), or else (a 1.0 file) what PROJ reads from the WKT, in the
// form GDAL gives at ingest, "NAME (AUTHORITY:CODE)". "" without a CRS; "unnamed CRS" where PROJ reads no name.
std::string crsName(const hc::Grid& g) {
    if (!g.crsName.empty() || g.crsWkt.empty()) return g.crsName;
    PJ_CONTEXT* ctx = proj_context_create();
    proj_log_level(ctx, PJ_LOG_NONE);  // a WKT that PROJ cannot read gets "unnamed CRS", not a log line on stderr
    PJ* crs = proj_create_from_wkt(ctx, g.crsWkt.c_str(), nullptr, nullptr, nullptr);
    const char* name = crs ? proj_get_name(crs) : nullptr;
    std::string label = name ? name : "unnamed CRS";
    const char* authority = crs ? proj_get_id_auth_name(crs, 0) : nullptr;
    const char* code = crs ? proj_get_id_code(crs, 0) : nullptr;
    if (authority && code) label += std::string(" (") + authority + ":" + code + ")";
    proj_destroy(crs);
    proj_context_destroy(ctx);
    return label;
}

std::string hex16(uint64_t v) {
    char b[20];
    std::snprintf(b, sizeof b, "%016" PRIx64, v);
    return b;
}

void printJson(const hc::GridFileInfo& info, const Summary& s, const std::string& path) {
    const hc::Grid& g = info.shape;
    nlohmann::ordered_json j;
    j["file"] = path;
    j["format_version"] = std::to_string(hc::kGridFileMajor) + "." + std::to_string(info.fileMinor);
    j["verified"] = info.verified;  // false: header, table and META checked, cells and values not (--verify)
    if (info.verified) j["valid"] = true;
    j["checked"] = checkedLine(info);
    j["cells"] = info.cellCount;
    j["levels"] = nlohmann::ordered_json::array();
    for (size_t l = 0; l < info.summary.cellsPerLevel.size(); ++l)
        j["levels"].push_back(
            {{"level", l}, {"size_m", g.levelSizeM(int(l))}, {"cells", info.summary.cellsPerLevel[l]}});
    j["min_cell_m"] = s.minCell;
    j["max_cell_m"] = s.maxCell;
    j["finest_cell_m"] = g.finestCellM;
    j["root_level"] = g.rootLevel;
    j["domain_m"] = g.domainSizeM();
    j["origin"] = {g.originWorldX, g.originWorldY};
    j["rotation_deg"] = g.rotationDeg;  // counterclockwise from the CRS's x axis, about the origin (UGRID meshes)
    j["crs_wkt"] = g.crsWkt;
    j["crs_name"] = crsName(g);
    j["extent"] = s.extent;
    j["layers"] = nlohmann::ordered_json::array();
    for (size_t l = 0; l < g.layers.size(); ++l) {
        nlohmann::ordered_json layer{{"name", g.layers[l].name}, {"units", g.layers[l].units}};
        if (l < info.summary.layerMin.size()) {
            layer["min"] = info.summary.layerMin[l];
            layer["max"] = info.summary.layerMax[l];
        }
        j["layers"].push_back(layer);
    }
    // Water steps (docs/design.md section 6): a 1.2 file's water layer, or a grid written from memory, is one step at 0
    // s.
    j["steps"] = nlohmann::ordered_json::array();
    for (size_t k = 0; k < g.steps.size(); ++k)
        j["steps"].push_back({{"step", k}, {"time_s", g.steps[k].timeS}, {"wet_cells", g.steps[k].wetCells}});
    if (!g.steps.empty()) j["step"] = g.step;  // the step whose values "layers" and "content_hash" describe
    j["source"] = g.stats.sourcePath;
    j["source_crs"] = g.stats.sourceCrsName;
    j["source_kind"] = g.stats.sourceKind.empty() ? "raster" : g.stats.sourceKind;
    if (!g.stats.sourceFormat.empty()) j["source_format"] = g.stats.sourceFormat;
    if (g.stats.latticeResidualM >= 0) j["lattice_residual_m"] = g.stats.latticeResidualM;
    j["valid_pixels"] = g.stats.validPixels;  // a mesh: its faces with terrain
    if (g.stats.sourceKind.empty()) {         // a mesh is taken as it is: no tolerance, nothing deviates
        j["tolerance_m"] = g.stats.toleranceM;
        j["max_dev_m"] = g.stats.maxDevM;
        j["rms_dev_m"] = g.stats.rmsDevM;
    }
    j["structure_hash"] = hex16(info.structureHash);
    j["content_hash"] = hex16(info.contentHash);
    j["bytes_checked"] = info.bytesChecked;
    // Paths and names are bytes from the file system and the file: any that are not UTF-8 are printed with
    // U+FFFD in their place rather than refused.
    std::fputs((j.dump(2, ' ', false, nlohmann::ordered_json::error_handler_t::replace) + "\n").c_str(), stdout);
}

void printText(const hc::GridFileInfo& info, const Summary& s, const std::string& path) {
    const hc::Grid& g = info.shape;
    std::printf("%s: heightcast grid, format %d.%d, %s\n", path.c_str(), hc::kGridFileMajor, info.fileMinor,
                checkedLine(info).c_str());
    std::printf("  cells        %llu, %zu layer%s:", (unsigned long long)info.cellCount, g.layerCount(),
                g.layerCount() == 1 ? "" : "s");
    for (const auto& l : g.layers) std::printf(" %s [%s]", l.name.c_str(), l.units.c_str());
    std::printf("\n  cell sizes   %.6g .. %.6g m (finest %.6g m, domain %.6g m = 2^%d finest)\n", s.minCell, s.maxCell,
                g.finestCellM, g.domainSizeM(), g.rootLevel);
    for (size_t l = 0; l < info.summary.cellsPerLevel.size(); ++l)
        std::printf("    level %zu  %10.4g m  %10llu cells\n", l, g.levelSizeM(int(l)),
                    (unsigned long long)info.summary.cellsPerLevel[l]);
    for (size_t l = 0; l < info.summary.layerMin.size(); ++l)
        std::printf(
            "  values       %s %.9g .. %.9g %s%s\n", g.layers[l].name.c_str(), double(info.summary.layerMin[l]),
            double(info.summary.layerMax[l]), g.layers[l].units.c_str(),
            !g.steps.empty() && l >= g.firstStepLayer() ? (" (step " + std::to_string(g.step) + ")").c_str() : "");
    if (!g.steps.empty()) {
        uint64_t lo = UINT64_MAX, hi = 0;
        for (const auto& st : g.steps) lo = std::min(lo, st.wetCells), hi = std::max(hi, st.wetCells);
        std::printf("  steps        %zu water step%s, %.9g .. %.9g s, %llu .. %llu wet cells (--json lists each)\n",
                    g.steps.size(), g.steps.size() == 1 ? "" : "s", g.steps.front().timeS, g.steps.back().timeS,
                    (unsigned long long)lo, (unsigned long long)hi);
    }
    std::printf("  origin       %.17g, %.17g\n", g.originWorldX, g.originWorldY);
    if (g.rotationDeg != 0)
        std::printf(
            "  rotation     %.17g degrees (the grid's axes, counterclockwise from the CRS's, about the origin)\n",
            g.rotationDeg);
    std::printf("  extent       %.17g, %.17g .. %.17g, %.17g\n", s.extent[0], s.extent[1], s.extent[2], s.extent[3]);
    std::string crs = g.crsWkt.empty() ? "none (local metres)" : crsName(g) + " (full WKT: --json)";
    std::printf("  CRS          %s\n", crs.c_str());
    const char* sourceCrs = g.stats.sourceCrsName.empty() ? "no CRS" : g.stats.sourceCrsName.c_str();
    if (!g.stats.sourceKind.empty()) {
        std::printf(
            "  source       %s (%s, %s); %llu faces taken as cells as they are (no merging, no resampling: no "
            "deviation)\n",
            g.stats.sourcePath.c_str(),
            g.stats.sourceFormat.empty() ? g.stats.sourceKind.c_str() : g.stats.sourceFormat.c_str(), sourceCrs,
            (unsigned long long)g.stats.validPixels);
        if (g.stats.latticeResidualM >= 0)
            std::printf("  lattice      every node within %.3g m of the lattice fitted to the faces\n",
                        g.stats.latticeResidualM);
    } else {
        if (!g.stats.sourceFormat.empty())
            std::printf("  model        %s, sampled onto the working raster\n", g.stats.sourceFormat.c_str());
        std::printf("  source       %s (%s); working raster %llu x %llu px, %llu valid\n", g.stats.sourcePath.c_str(),
                    sourceCrs, (unsigned long long)g.stats.sourceWidth, (unsigned long long)g.stats.sourceHeight,
                    (unsigned long long)g.stats.validPixels);
        std::printf("  deviation    max %.6g m, RMS %.6g m (tolerance %.6g m)\n", g.stats.maxDevM, g.stats.rmsDevM,
                    g.stats.toleranceM);
    }
    std::printf("  hashes       structure %016" PRIx64 ", content %016" PRIx64 "%s\n", info.structureHash,
                info.contentHash, info.verified ? "" : " (as stored)");
    std::printf("  checked      checksums of %llu section bytes (the file has %llu)\n",
                (unsigned long long)info.bytesChecked, (unsigned long long)info.fileBytes);
}

void writeCsv(const hc::Grid& g, const std::string& path) {
    hc::AtomicFileWriter out(path);
    std::string line = "x,y,size,level,elevation";
    for (size_t l = 1; l < g.layers.size(); ++l) line += "," + g.layers[l].name;
    line += "\n";
    std::string buf;
    buf.reserve(1 << 20);
    buf += line;
    char cell[128];
    for (size_t i = 0; i < g.cellCount(); ++i) {
        double x, y;
        g.cellCenterLocal(i, x, y);
        g.localToWorld(x, y, x, y);
        std::snprintf(cell, sizeof cell, "%.17g,%.17g,%.17g,%d", x, y, g.cellSizeM(i), g.level(i));
        buf += cell;
        for (size_t l = 0; l < g.layers.size(); ++l) {
            std::snprintf(cell, sizeof cell, ",%.9g", double(g.values[l][i]));  // 9 digits: float32 round-trips
            buf += cell;
        }
        buf += '\n';
        if (buf.size() > (1 << 20) - 256) {
            out.write(std::as_bytes(std::span(buf)));
            buf.clear();
        }
    }
    out.write(std::as_bytes(std::span(buf)));
    out.commit();
}

}  // namespace

int main(int argc, char** argv) {
    return hc::cli::run("hc-info", [&] {
        std::string path, csv;
        bool json = false, verify = false;
        unsigned step = 0;
        hc::cli::Parser p(
            "hc-info", "FILE.hcg [--verify] [--json] [--cells-csv OUT.csv]",
            "Prints a heightcast grid file's header and statistics. From format 1.2 on these are read from the\n"
            "header and META without reading the cells (milliseconds at any size): the first line then says that\n"
            "cells and values were not verified. --verify (or --cells-csv, which reads every cell) checks all of\n"
            "the file: every checksum, every cell invariant, both hashes and the stored summary. A 1.0/1.1 file\n"
            "has no stored summary and is always read and checked in full. Exits non-zero, naming the byte\n"
            "offset, if anything checked is wrong.");
        p.positional("FILE.hcg", "grid file to inspect", path);
        p.flag("--verify",
               "check the whole file (reads all of it: seconds per GB); default: header, table and META only", verify);
        p.flag("--json",
               "print the summary as JSON (keys: verified, checked, cells, levels, min_cell_m, max_cell_m, origin,\n"
               "      crs_wkt, crs_name, extent, layers (with min, max), steps (step, time_s, wet_cells), step, "
               "tolerance_m, max_dev_m,\n"
               "      rms_dev_m, ...)",
               json);
        p.option("--step", "K", "water step whose values the ranges, hash and cells CSV show, 0-based (default 0)",
                 step);
        p.option("--cells-csv", "OUT.csv",
                 "write one line per cell: x,y,size,level,elevation[,layers...] (cell centres in the\n"
                 "      grid CRS, metres, full double precision); implies --verify",
                 csv);
        if (!p.parse(argc, argv)) return 0;
        if (!csv.empty()) {
            hc::cli::checkWritable(csv, "cells CSV");
            hc::cli::checkNotSame(csv, path, "cells CSV");
        }
        const hc::GridFileInfo info =
            verify || !csv.empty() ? hc::verifyGridFile(path, step) : hc::readGridInfo(path, step);
        const Summary s = summarise(info);
        if (json)
            printJson(info, s, path);
        else
            printText(info, s, path);
        if (!csv.empty()) writeCsv(*info.grid, csv);
        return 0;
    });
}
