// hc-info: header, statistics and full validation of a grid file; JSON and per-cell CSV export.
#include <cinttypes>
#include <cstdio>
#include <filesystem>
#include <string>

#include "cli.h"
#include "heightcast/core/atomic_file.h"
#include "heightcast/core/error.h"
#include "heightcast/grid/grid_file.h"

namespace {

std::string jsonString(const std::string& s) {
    std::string o = "\"";
    for (unsigned char c : s) {
        switch (c) {
            case '"': o += "\\\""; break;
            case '\\': o += "\\\\"; break;
            case '\n': o += "\\n"; break;
            case '\r': o += "\\r"; break;
            case '\t': o += "\\t"; break;
            default:
                if (c < 0x20) {
                    char b[8];
                    std::snprintf(b, sizeof b, "\\u%04x", c);
                    o += b;
                } else {
                    o += static_cast<char>(c);
                }
        }
    }
    return o + "\"";
}

std::string num(double v) {
    char b[40];
    std::snprintf(b, sizeof b, "%.17g", v);
    return b;
}

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

void printJson(const hc::Grid& g, const Summary& s, const std::string& path) {
    std::string j = "{\n";
    j += "  \"file\": " + jsonString(path) + ",\n";
    j += "  \"format_version\": \"" + std::to_string(hc::kGridFileMajor) + "." + std::to_string(s.fileMinor) + "\",\n";
    j += "  \"valid\": true,\n";
    j += "  \"cells\": " + std::to_string(g.cellCount()) + ",\n";
    j += "  \"levels\": [";
    for (size_t l = 0; l < s.perLevel.size(); ++l)
        j += std::string(l ? ", " : "") + "{\"level\": " + std::to_string(l) + ", \"size_m\": " + num(g.levelSizeM(int(l))) +
             ", \"cells\": " + std::to_string(s.perLevel[l]) + "}";
    j += "],\n";
    j += "  \"min_cell_m\": " + num(s.minCell) + ",\n";
    j += "  \"max_cell_m\": " + num(s.maxCell) + ",\n";
    j += "  \"finest_cell_m\": " + num(g.finestCellM) + ",\n";
    j += "  \"root_level\": " + std::to_string(g.rootLevel) + ",\n";
    j += "  \"domain_m\": " + num(g.domainSizeM()) + ",\n";
    j += "  \"origin\": [" + num(g.originWorldX) + ", " + num(g.originWorldY) + "],\n";
    j += "  \"crs_wkt\": " + jsonString(g.crsWkt) + ",\n";
    j += "  \"extent\": [" + num(s.extent[0]) + ", " + num(s.extent[1]) + ", " + num(s.extent[2]) + ", " + num(s.extent[3]) + "],\n";
    j += "  \"layers\": [";
    for (size_t l = 0; l < g.layers.size(); ++l)
        j += std::string(l ? ", " : "") + "{\"name\": " + jsonString(g.layers[l].name) + ", \"units\": " + jsonString(g.layers[l].units) + "}";
    j += "],\n";
    j += "  \"source\": " + jsonString(g.stats.sourcePath) + ",\n";
    j += "  \"source_crs\": " + jsonString(g.stats.sourceCrsName) + ",\n";
    j += "  \"valid_pixels\": " + std::to_string(g.stats.validPixels) + ",\n";
    j += "  \"tolerance_m\": " + num(g.stats.toleranceM) + ",\n";
    j += "  \"max_dev_m\": " + num(g.stats.maxDevM) + ",\n";
    j += "  \"rms_dev_m\": " + num(g.stats.rmsDevM) + ",\n";
    char hash[40];
    std::snprintf(hash, sizeof hash, "%016" PRIx64, g.structureHash());
    j += "  \"structure_hash\": \"" + std::string(hash) + "\",\n";
    std::snprintf(hash, sizeof hash, "%016" PRIx64, g.contentHash());
    j += "  \"content_hash\": \"" + std::string(hash) + "\"\n}\n";
    std::fputs(j.c_str(), stdout);
}

// "NAME (EPSG:CODE)" from a WKT: its first quoted string and its last top-level ID.
std::string crsLabel(const std::string& wkt) {
    auto q0 = wkt.find('"'), q1 = q0 == std::string::npos ? q0 : wkt.find('"', q0 + 1);
    std::string label = q1 == std::string::npos ? "unnamed CRS" : wkt.substr(q0 + 1, q1 - q0 - 1);
    auto id = wkt.rfind("ID[\"");
    if (id != std::string::npos && wkt.find("]]", id) != std::string::npos && wkt.find(']', id) + 1 >= wkt.size() - 2) {
        auto a0 = id + 4, a1 = wkt.find('"', a0), c0 = wkt.find(',', a1), c1 = wkt.find(']', c0);
        if (a1 != std::string::npos && c0 != std::string::npos && c1 != std::string::npos)
            label += " (" + wkt.substr(a0, a1 - a0) + ":" + wkt.substr(c0 + 1, c1 - c0 - 1) + ")";
    }
    return label;
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
    std::string crs = g.crsWkt.empty() ? "none (local metres)" : crsLabel(g.crsWkt) + " (full WKT: --json)";
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
        p.flag("--json", "print the summary as JSON (keys: cells, levels, min_cell_m, max_cell_m, origin, crs_wkt, extent,\n"
               "      layers, tolerance_m, max_dev_m, rms_dev_m, ...)", json);
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
