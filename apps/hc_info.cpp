// hc-info: header, statistics and full validation of a grid file; JSON and per-cell CSV export.
#include <cinttypes>
#include <cstdio>
#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>
#include <proj.h>

#include "cli.h"
#include "heightcast/core/atomic_file.h"
#include "heightcast/core/error.h"
#include "heightcast/grid/grid_file.h"

namespace {

struct Summary {
    uint16_t fileMinor = 0;  // the file's format minor version (major is kGridFileMajor, or it would not read)
    double minCell = 0, maxCell = 0;
    double extent[4] = {0, 0, 0, 0};  // world xmin, ymin, xmax, ymax
    std::vector<uint64_t> perLevel;
};

Summary summarise(const hc::Grid& g) {
    Summary s;
    s.perLevel = g.cellsPerLevel();
    int lo = -1, hi = -1;
    for (size_t l = 0; l < s.perLevel.size(); ++l)
        if (s.perLevel[l]) {
            if (lo < 0) lo = int(l);
            hi = int(l);
        }
    if (lo >= 0) {
        s.minCell = g.levelSizeM(lo);
        s.maxCell = g.levelSizeM(hi);
    }
    double x0, y0, x1, y1;
    g.boundsLocal(x0, y0, x1, y1);
    s.extent[0] = g.originWorldX + x0;
    s.extent[1] = g.originWorldY + y0;
    s.extent[2] = g.originWorldX + x1;
    s.extent[3] = g.originWorldY + y1;
    return s;
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

void printJson(const hc::Grid& g, const Summary& s, const std::string& path) {
    nlohmann::ordered_json j;
    j["file"] = path;
    j["format_version"] = std::to_string(hc::kGridFileMajor) + "." + std::to_string(s.fileMinor);
    j["valid"] = true;
    j["cells"] = g.cellCount();
    j["levels"] = nlohmann::ordered_json::array();
    for (size_t l = 0; l < s.perLevel.size(); ++l)
        j["levels"].push_back({{"level", l}, {"size_m", g.levelSizeM(int(l))}, {"cells", s.perLevel[l]}});
    j["min_cell_m"] = s.minCell;
    j["max_cell_m"] = s.maxCell;
    j["finest_cell_m"] = g.finestCellM;
    j["root_level"] = g.rootLevel;
    j["domain_m"] = g.domainSizeM();
    j["origin"] = {g.originWorldX, g.originWorldY};
    j["crs_wkt"] = g.crsWkt;
    j["crs_name"] = crsName(g);
    j["extent"] = s.extent;
    j["layers"] = nlohmann::ordered_json::array();
    for (const auto& l : g.layers) j["layers"].push_back({{"name", l.name}, {"units", l.units}});
    j["source"] = g.stats.sourcePath;
    j["source_crs"] = g.stats.sourceCrsName;
    j["valid_pixels"] = g.stats.validPixels;
    j["tolerance_m"] = g.stats.toleranceM;
    j["max_dev_m"] = g.stats.maxDevM;
    j["rms_dev_m"] = g.stats.rmsDevM;
    j["structure_hash"] = hex16(g.structureHash());
    j["content_hash"] = hex16(g.contentHash());
    // Paths and names are bytes from the file system and the file: any that are not UTF-8 are printed with
    // U+FFFD in their place rather than refused.
    std::fputs((j.dump(2, ' ', false, nlohmann::ordered_json::error_handler_t::replace) + "\n").c_str(), stdout);
}

void printText(const hc::Grid& g, const Summary& s, const std::string& path) {
    std::printf("%s: heightcast grid, format %d.%d, valid (all checksums and invariants checked)\n", path.c_str(),
                hc::kGridFileMajor, s.fileMinor);
    std::printf("  cells        %zu, %zu layer%s:", g.cellCount(), g.layerCount(), g.layerCount() == 1 ? "" : "s");
    for (const auto& l : g.layers) std::printf(" %s [%s]", l.name.c_str(), l.units.c_str());
    std::printf("\n  cell sizes   %.6g .. %.6g m (finest %.6g m, domain %.6g m = 2^%d finest)\n", s.minCell, s.maxCell,
                g.finestCellM, g.domainSizeM(), g.rootLevel);
    for (size_t l = 0; l < s.perLevel.size(); ++l)
        std::printf("    level %zu  %10.4g m  %10llu cells\n", l, g.levelSizeM(int(l)), (unsigned long long)s.perLevel[l]);
    std::printf("  origin       %.17g, %.17g\n", g.originWorldX, g.originWorldY);
    std::printf("  extent       %.17g, %.17g .. %.17g, %.17g\n", s.extent[0], s.extent[1], s.extent[2], s.extent[3]);
    std::string crs = g.crsWkt.empty() ? "none (local metres)" : crsName(g) + " (full WKT: --json)";
    std::printf("  CRS          %s\n", crs.c_str());
    std::printf("  source       %s (%s); working raster %llu x %llu px, %llu valid\n", g.stats.sourcePath.c_str(),
                g.stats.sourceCrsName.empty() ? "no CRS" : g.stats.sourceCrsName.c_str(),
                (unsigned long long)g.stats.sourceWidth, (unsigned long long)g.stats.sourceHeight,
                (unsigned long long)g.stats.validPixels);
    std::printf("  deviation    max %.6g m, RMS %.6g m (tolerance %.6g m)\n", g.stats.maxDevM, g.stats.rmsDevM, g.stats.toleranceM);
    std::printf("  hashes       structure %016" PRIx64 ", content %016" PRIx64 "\n", g.structureHash(), g.contentHash());
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
        std::snprintf(cell, sizeof cell, "%.17g,%.17g,%.17g,%d", g.originWorldX + x, g.originWorldY + y, g.cellSizeM(i), g.level(i));
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
        bool json = false;
        hc::cli::Parser p("hc-info", "FILE.hcg [--json] [--cells-csv OUT.csv]",
                          "Reads a heightcast grid file, validates all of it (header, checksums, every cell) and prints its\n"
                          "header and statistics. Exits non-zero, naming the byte offset, if anything is wrong.");
        p.positional("FILE.hcg", "grid file to inspect", path);
        p.flag("--json", "print the summary as JSON (keys: cells, levels, min_cell_m, max_cell_m, origin, crs_wkt, crs_name,\n"
               "      extent, layers, tolerance_m, max_dev_m, rms_dev_m, ...)", json);
        p.option("--cells-csv", "OUT.csv", "write one line per cell: x,y,size,level,elevation[,layers...] (cell centres in the\n"
                 "      grid CRS, metres, full double precision)", csv);
        if (!p.parse(argc, argv)) return 0;
        if (!csv.empty()) {
            hc::cli::checkWritable(csv, "cells CSV");
            hc::cli::checkNotSame(csv, path, "cells CSV");
        }
        uint16_t fileMinor = 0;
        hc::Grid g = hc::readGrid(path, &fileMinor);
        Summary s = summarise(g);
        s.fileMinor = fileMinor;
        if (json)
            printJson(g, s, path);
        else
            printText(g, s, path);
        if (!csv.empty()) writeCsv(g, csv);
        return 0;
    });
}
