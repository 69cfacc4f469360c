// bench/bench_influence.h: what hc-bench-influence's files share: the CSV every table writes, the evaluation's tallies
// (bench_influence.cpp: tables 1 and 2, and main), and table 3, the smooth surface's accuracy against the source
// rasters (bench_influence_accuracy.cpp).
#pragma once

#include <algorithm>
#include <cstdint>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include "heightcast/core/error.h"
#include "heightcast/grid/grid.h"

namespace hc::bench::influence {

// One CSV for every table: a fixed set of columns, each row filling the ones that apply.
class Csv {
public:
    using Row = std::map<std::string, std::string>;
    void add(Row row) { rows_.push_back(std::move(row)); }
    void write(const std::string& path) const {
        static const char* columns[] = {"table",
                                        "grid",
                                        "source",
                                        "tolerance_m",
                                        "sigma",
                                        "truncation",
                                        "max_cell_m",
                                        "threads",
                                        "working_px",
                                        "pixel_m",
                                        "valid_px",
                                        "cells",
                                        "cells_per_valid_px",
                                        "min_cell_m",
                                        "coarsest_cell_m",
                                        "build_ms",
                                        "m_cells_per_s",
                                        "entries_mean",
                                        "entries_p99",
                                        "entries_max",
                                        "lists_mb",
                                        "order",
                                        "points",
                                        "defined_fraction",
                                        "eval_ms",
                                        "m_points_per_s",
                                        "grid_rms_m",
                                        "grid_max_m",
                                        "surface_rms_m",
                                        "surface_max_m",
                                        "sampled",
                                        "target"};
        std::ofstream f(path);
        if (!f) throw hc::Error(path + ": cannot open for writing (--csv)");
        for (size_t c = 0; c < std::size(columns); ++c) f << (c ? "," : "") << columns[c];
        f << "\n";
        for (const Row& r : rows_) {
            for (size_t c = 0; c < std::size(columns); ++c) {
                auto it = r.find(columns[c]);
                f << (c ? "," : "") << (it == r.end() ? "" : it->second);
            }
            f << "\n";
        }
        if (!f.flush()) throw hc::Error(path + ": write failed (--csv)");
    }

private:
    std::vector<Row> rows_;
};

// The evaluation's tallies: one per worker, on its own cache line.
struct alignas(64) Accum {
    uint64_t defined = 0, undefined = 0;
    double sum = 0;                        // of values: keeps the work observable
    double sumSq = 0, maxAbs = 0;          // surface - pixel
    double gridSumSq = 0, gridMaxAbs = 0;  // covering cell - pixel (cross-check of Grid::stats)
};

inline Accum reduce(const std::vector<Accum>& parts) {
    Accum a;
    for (const Accum& p : parts) {
        a.defined += p.defined;
        a.undefined += p.undefined;
        a.sum += p.sum;
        a.sumSq += p.sumSq;
        a.maxAbs = std::max(a.maxAbs, p.maxAbs);
        a.gridSumSq += p.gridSumSq;
        a.gridMaxAbs = std::max(a.gridMaxAbs, p.gridMaxAbs);
    }
    return a;
}

// "0.75..96": the smallest and largest cell size present [m].
inline std::string levelRange(const hc::Grid& g) {
    const auto per = g.cellsPerLevel();
    int lo = -1, hi = -1;
    for (size_t l = 0; l < per.size(); ++l)
        if (per[l]) {
            if (lo < 0) lo = static_cast<int>(l);
            hi = static_cast<int>(l);
        }
    if (lo < 0) return "empty";
    return fmt::format("{:.4g}..{:.4g}", g.levelSizeM(lo), g.levelSizeM(hi));
}

// Table 3's settings (hc-bench-influence's options).
struct AccuracyOptions {
    std::vector<std::string> dems;
    std::vector<double> tolerances, sigmas;
    double maxCellM = 768, truncation = 3.5;
    int maxEvalPx = 2000000;
    unsigned threads = 0, allThreads = 1;
};
// Table 3: every DEM ingested at every tolerance, its smooth surface at every sigma against every valid pixel (or a
// sample), printed, its rows added to `out`, and plotted to `plot` when not "".
void accuracyTable(const AccuracyOptions& o, Csv& out, const std::string& plot);

}  // namespace hc::bench::influence
