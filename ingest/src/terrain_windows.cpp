// ingest/src/terrain_windows.cpp: the terrain's working raster read window by window (detail::TerrainWindows,
// heightcast/ingest/detail/windows.h), as the ranks of an MPI run read it: a source kept as is (KeptWindows), or
// resampled, projected or warped on the whole working raster's lattice (ResampledWindows), so that a window holds the
// same bits as the whole raster there; and openTerrainWindows, which picks one by the route load_terrain.cpp decided.
#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>

#include "heightcast/core/error.h"
#include "heightcast/core/parallel.h"
#include "heightcast/core/progress.h"
#include "heightcast/core/ranks.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/ingest/ingest.h"
#include "load_terrain_internal.h"
#include "resample.h"

namespace hc::ingest {

namespace {

using detail::keptGeometry;
using detail::kNaN;
using detail::Opened;
using detail::planWarp;
using detail::Resampling;
using detail::WarpedFrame;
using detail::warpedFrame;
using detail::WarpPlan;
using detail::warpRowToWorld;

// TerrainWindows over a source kept as is: a working window is the same window of the source, mirrored where the
// source runs south-up or east-to-west.
class KeptWindows final : public detail::TerrainWindows {
public:
    KeptWindows(Opened&& o, LoadReport& report) : o_(std::move(o)) {
        shape_.crsWkt = o_.wkt;
        shape_.crsName = report.gridCrsName;
        keptGeometry(o_.gt, o_.band->width(), o_.band->height(), shape_, flipX_, flipY_, report);
    }
    const Raster& shape() const override { return shape_; }
    void read(size_t col0, size_t row0, size_t w, size_t h, std::vector<float>& values, std::vector<float>& rounding,
              bool first) override {
        if (col0 + w > shape_.width || row0 + h > shape_.height) throw Error("window outside the working raster");
        const size_t c0 = flipX_ ? shape_.width - col0 - w : col0, r0 = flipY_ ? shape_.height - row0 - h : row0;
        values.assign(w * h, kNaN);
        rounding.clear();
        // Whole rows of blocks at a time, about 4 MB, GDAL's copy of them dropped after each: a large window held no
        // second copy of itself in GDAL's cache, whose freed blocks then came back as fresh pages to fault in.
        detail::SourceTally again;  // a window read a second time is counted once
        const size_t block = o_.band->blockRows();
        const size_t chunk = std::max<size_t>(1, (size_t{4} << 20) / (w * sizeof(float)) / block) * block;
        for (size_t r = r0; r < r0 + h;) {
            const size_t next = std::min(r0 + h, (r / block + chunk / block) * block);
            o_.band->read(c0, r, w, next - r, values.data() + (r - r0) * w, rounding, (r - r0) * w, w * h,
                          first ? tally_ : again);
            o_.band->dropCache();
            r = next;
        }
        if (flipX_ || flipY_) {
            auto mirror = [&](std::vector<float>& v) {
                if (v.empty()) return;
                std::vector<float> m(v.size());
                for (size_t r = 0; r < h; ++r)
                    for (size_t c = 0; c < w; ++c)
                        m[r * w + c] = v[(flipY_ ? h - 1 - r : r) * w + (flipX_ ? w - 1 - c : c)];
                v.swap(m);
            };
            mirror(values);
            mirror(rounding);
        }
    }
    const detail::SourceTally& tally() const override { return tally_; }
    void finish(const detail::SourceTally& all, LoadReport& report) const override { o_.band->finish(all, report); }

private:
    Opened o_;
    Raster shape_;
    bool flipX_ = false, flipY_ = false;
    detail::SourceTally tally_;
};

// TerrainWindows over a source that is resampled (projected to UTM, rotated, non-square pixels or --min-cell): a
// working window reads the source pixels its map reaches (resampleWindow asks for them) and resamples them on the whole
// target's lattice, so its pixels are the same bits as the whole raster's (resample.h). The reading tally counts every
// source pixel once: each rank reads its share of the source's row strips for it (one more pass over the source, spread
// over the ranks), and in the same pass, once the grid file is written, checks those pixels against the cells under
// their centres (LoadReport::sourceCheck), each strip against the file's region under it.
class ResampledWindows final : public detail::TerrainWindows {
public:
    ResampledWindows(Opened&& o, Resampling&& plan, const Options& opt, LoadReport& report)
        : o_(std::move(o)), plan_(std::move(plan)), threads_(opt.threads), progress_(opt.progress) {
        step_ = detail::latticeStep(plan_.shape, plan_.map, plan_.lattice, plan_.maxErrorPx, threads_);
        if (plan_.sayLattice) report.method += ", map exact every " + std::to_string(step_) + " px" + plan_.methodTail;
    }
    // --t_srs: the windows warped by GDAL (WarpPlan::warp), the source's blocks read as the warper asks for them.
    ResampledWindows(Opened&& o, const Options& opt, LoadReport& report)
        : o_(std::move(o)), threads_(opt.threads), progress_(opt.progress) {
        const size_t width = o_.band->width(), height = o_.band->height();
        auto fill = [this](size_t c0, size_t r0, size_t w, size_t h, float* out) {
            std::vector<float> residual;    // the warper takes float32 values (as read whole)
            detail::SourceTally uncounted;  // counted once by tally()
            o_.band->read(c0, r0, w, h, out, residual, 0, w * h, uncounted);
        };
        warp_ = std::make_unique<WarpPlan>(planWarp(o_.gt, width, height, o_.srs, o_.target, opt, report, fill));
        const WarpedFrame frame = warpedFrame(*warp_, report);
        Raster& r = plan_.shape;  // as fromSourceAffine keeps the warped raster (north-up, square: as is)
        r.crsWkt = detail::toWkt(frame.crs);
        r.crsName = report.gridCrsName;
        bool flipX = false, flipY = false;
        keptGeometry(frame.gt, warp_->width, warp_->height, r, flipX, flipY, report);
        plan_.rowToWorld = warpRowToWorld(*warp_, o_.gt, frame.unit);
        plan_.rowToWorldThreadSafe = false;
    }
    const Raster& shape() const override { return plan_.shape; }
    void checkValid(uint64_t validPixels) const override {
        if (warp_) warp_->checkValid(validPixels);
    }
    void read(size_t col0, size_t row0, size_t w, size_t h, std::vector<float>& values, std::vector<float>& rounding,
              bool /*first: the source is counted by stripPass*/) override {
        if (col0 + w > plan_.shape.width || row0 + h > plan_.shape.height)
            throw Error("window outside the working raster");
        values.assign(w * h, kNaN);
        rounding.clear();  // a resampled raster keeps float32 values only (as read whole)
        if (warp_) {
            warp_->warp(col0, row0, w, h, values.data());
            o_.band->dropCache();
            return;
        }
        const size_t width = o_.band->width(), height = o_.band->height();
        auto readSource = [&](size_t c0, size_t r0, size_t c1, size_t r1) {
            const size_t sw = c1 - c0 + 1, sh = r1 - r0 + 1;
            source_.assign(sw * sh, kNaN);
            residual_.clear();
            detail::SourceTally uncounted;  // counted once by tally()
            o_.band->read(c0, r0, sw, sh, source_.data(), residual_, 0, sw * sh, uncounted);
            o_.band->dropCache();
            return detail::SourceView{source_.data(), c0, r0, sw, width, height};
        };
        detail::resampleWindow(plan_.map, plan_.shape, step_, col0, row0, w, h, width, height, readSource,
                               values.data(), threads_);
    }
    const detail::SourceTally& tally() const override {
        if (!counted_) stripPass(nullptr, nullptr);
        return tally_;
    }
    std::optional<detail::SourceCheckSums> checkAgainst(const std::string& gridPath) override {
        const GridRegionReader grid(gridPath);
        detail::SourceCheckSums sums;
        stripPass(&grid, &sums);
        return sums;
    }
    void finish(const detail::SourceTally& all, LoadReport& report) const override { o_.band->finish(all, report); }

private:
    // One pass over this rank's share of the source's row strips (every source pixel once over the ranks): the tally,
    // and with `grid` the check of each valid pixel against the cell under its centre, as checkAgainstSource
    // (ingest.cpp) makes it in one process: the pixel's centre mapped to the working raster's pixel, whose cell is
    // read from the file (the region under the strip, painted onto that strip's pixels).
    void stripPass(const GridRegionReader* grid, detail::SourceCheckSums* sums) const {
        const size_t width = o_.band->width(), height = o_.band->height();
        const size_t strip = o_.band->stripRows(size_t{1} << 20);  // as read whole
        // A rank takes a run of strips: its rows' footprint is then one band of the working raster, and the file's
        // regions under them about its share of the file (every rank's strips spread over the height would each touch
        // nearly every page of the file, the cells of a band being spread over it in Morton order).
        const uint64_t strips = (height + strip - 1) / strip;
        const uint64_t s0 = ranks::shareBegin(strips, ranks::rank(), ranks::count()),
                       s1 = ranks::shareBegin(strips, ranks::rank() + 1, ranks::count());
        Progress progress(grid ? "checking the source's pixels against their cells" : "counting the source's pixels",
                          s1 - s0, progress_ && ranks::rank() == 0);
        std::vector<float> values, residual, painted;
        std::vector<int64_t> at;  // per strip pixel: its working pixel (row * width + col), or -1 where none
        tally_ = {};
        for (uint64_t s = s0; s < s1; ++s) {
            const size_t r0 = size_t(s) * strip, rows = std::min(strip, height - r0);
            values.assign(width * rows, kNaN);
            residual.clear();
            o_.band->read(0, r0, width, rows, values.data(), residual, 0, values.size(), tally_);
            o_.band->dropCache();
            if (grid) checkStrip(*grid, r0, rows, values, residual, at, painted, *sums);
            progress.advance(1);
        }
        progress.finish();
        counted_ = true;
    }

    // Rows [r0, r0 + rows) of the source (values, residual as read) against the file's cells, on every worker.
    void checkStrip(const GridRegionReader& grid, size_t r0, size_t rows, const std::vector<float>& values,
                    const std::vector<float>& residual, std::vector<int64_t>& at, std::vector<float>& painted,
                    detail::SourceCheckSums& sums) const {
        const Raster& t = plan_.shape;
        const size_t width = o_.band->width(), workers = resolveThreads(threads_);
        at.assign(width * rows, -1);
        struct Box {
            size_t c0 = SIZE_MAX, c1 = 0, w0 = SIZE_MAX, w1 = 0;  // the working pixels the centres reach
        };
        std::vector<Box> boxes(workers);
        parallelFor(rows, 4, plan_.rowToWorldThreadSafe ? threads_ : 1, [&](size_t b, size_t e, unsigned worker) {
            std::vector<double> x(width), y(width);
            std::vector<int> ok(width);
            Box& box = boxes[worker];
            for (size_t j = b; j < e; ++j) {
                plan_.rowToWorld(r0 + j, x, y, ok);
                for (size_t c = 0; c < width; ++c) {
                    if (std::isnan(values[j * width + c])) continue;
                    const int64_t p = detail::workingPixelAt(t, x[c], y[c], ok[c]);
                    if (p < 0) continue;
                    const size_t ic = size_t(p) % t.width, ir = size_t(p) / t.width;
                    at[j * width + c] = p;
                    box.c0 = std::min(box.c0, ic), box.c1 = std::max(box.c1, ic), box.w0 = std::min(box.w0, ir),
                    box.w1 = std::max(box.w1, ir);
                }
            }
        });
        Box all;
        for (const Box& box : boxes)
            all.c0 = std::min(all.c0, box.c0), all.c1 = std::max(all.c1, box.c1), all.w0 = std::min(all.w0, box.w0),
            all.w1 = std::max(all.w1, box.w1);
        const size_t c0 = all.c0, c1 = all.c1, w0 = all.w0, w1 = all.w1;
        const size_t bw = c0 <= c1 ? c1 - c0 + 1 : 0, bh = w0 <= w1 ? w1 - w0 + 1 : 0;
        painted.assign(bw * bh, kNaN);
        if (bw > 0) {
            // The cells under working pixels [c0, c1] x [w0, w1] (the grid's local frame: origin at the working
            // raster's south-west corner, y north, one finest cell a pixel), painted onto them.
            const double px = t.pixelSizeM;
            const Grid cells = grid.region(
                {double(c0) * px, double(t.height - 1 - w1) * px, double(c1 + 1) * px, double(t.height - w0) * px});
            for (size_t i = 0; i < cells.cellCount(); ++i) {
                const uint64_t key = codeKey(cells.codes[i]);
                const size_t span = size_t{1} << codeLevel(cells.codes[i]), ix0 = mortonX(key), iy0 = mortonY(key);
                for (size_t iy = iy0; iy < iy0 + span; ++iy) {
                    if (iy >= t.height) break;
                    const size_t row = t.height - 1 - iy;
                    if (row < w0 || row > w1) continue;
                    for (size_t ix = std::max(ix0, c0); ix < std::min(ix0 + span, c1 + 1); ++ix)
                        painted[(row - w0) * bw + (ix - c0)] = cells.values[0][i];
                }
            }
        }
        std::vector<detail::SourceCheckSums> parts(workers);
        parallelFor(rows, 4, threads_, [&](size_t b, size_t e, unsigned worker) {
            detail::SourceCheckSums& p = parts[worker];
            for (size_t i = b * width; i < e * width; ++i) {
                if (std::isnan(values[i])) continue;
                const float z =
                    at[i] < 0 ? kNaN : painted[(size_t(at[i]) / t.width - w0) * bw + (size_t(at[i]) % t.width - c0)];
                p.addPixel(double(values[i]) + (residual.empty() ? 0.0 : double(residual[i])), z);
            }
        });
        for (const auto& p : parts) sums.add(p);
    }

    Opened o_;
    Resampling plan_;
    std::unique_ptr<WarpPlan> warp_;  // --t_srs
    unsigned threads_;
    bool progress_;
    int step_ = 1;
    std::vector<float> source_, residual_;
    mutable detail::SourceTally tally_;
    mutable bool counted_ = false;
};

}  // namespace

std::unique_ptr<detail::TerrainWindows> detail::openTerrainWindows(const Options& opt, LoadReport& report) {
    Opened o = openTerrain(opt, report);
    const size_t width = o.band->width(), height = o.band->height();
    switch (o.route) {
        case Opened::Route::Warp: {
            return std::make_unique<ResampledWindows>(std::move(o), opt, report);
        }
        case Opened::Route::Utm: {
            Resampling plan = planUtm(o.gt, width, height, o.srs, opt, report, false);
            return std::make_unique<ResampledWindows>(std::move(o), std::move(plan), opt, report);
        }
        case Opened::Route::Affine:
            break;
    }
    if (!keptAsIs(o.gt, opt)) {
        Resampling plan = planAffine(o.gt, width, height, o.pixelM, o.wkt, opt, report, false);
        return std::make_unique<ResampledWindows>(std::move(o), std::move(plan), opt, report);
    }
    return std::make_unique<KeptWindows>(std::move(o), report);
}

}  // namespace hc::ingest
