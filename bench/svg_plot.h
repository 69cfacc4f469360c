// bench/svg_plot.h: the benchmarks' plots, as self-contained SVG files (no plotting library to install;
// any browser or image viewer opens them). Two kinds: lines with markers over linear or logarithmic axes
// (LinePlot), and horizontal stacked bars (BarPlot). Written atomically, like every output of the toolkit.
#pragma once

#include <algorithm>
#include <cmath>
#include <span>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "heightcast/core/atomic_file.h"
#include "heightcast/core/error.h"

namespace hc::bench {

// Distinct colours that stay apart for colour-blind readers (Okabe-Ito), then repeat.
inline const char* plotColor(size_t i) {
    static const char* colors[] = {"#0072B2", "#D55E00", "#009E73", "#CC79A7",
                                   "#E69F00", "#56B4E9", "#000000", "#F0E442"};
    return colors[i % (sizeof colors / sizeof *colors)];
}

inline std::string svgEscape(const std::string& s) {
    std::string out;
    for (char c : s) {
        if (c == '<')
            out += "&lt;";
        else if (c == '>')
            out += "&gt;";
        else if (c == '&')
            out += "&amp;";
        else
            out += c;
    }
    return out;
}

inline std::string svgNum(double v) { return fmt::format("{:.2f}", v); }

// A tick label: 3 significant digits, no trailing zeros.
inline std::string tickLabel(double v) { return fmt::format("{:.3g}", v); }

// About six ticks over [lo, hi] at a round step (1, 2 or 5 times a power of ten).
inline std::vector<double> linearTicks(double lo, double hi) {
    const double raw = (hi - lo) / 6, mag = std::pow(10.0, std::floor(std::log10(raw)));
    const double step = raw / mag < 2 ? 2 * mag : raw / mag < 5 ? 5 * mag : 10 * mag;
    std::vector<double> t;
    for (double v = std::ceil(lo / step) * step; v <= hi; v += step) t.push_back(std::abs(v) < 1e-12 * step ? 0.0 : v);
    return t;
}

// An SVG document's start: the canvas, a white background and the title above the plot's left edge.
inline std::string svgStart(double width, double height, double left, const std::string& title) {
    return "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" + svgNum(width) + "\" height=\"" + svgNum(height) +
           "\" font-family=\"sans-serif\" font-size=\"12\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n" +
           "<text x=\"" + svgNum(left) + "\" y=\"28\" font-size=\"15\">" + svgEscape(title) + "</text>\n";
}

inline void writeSvg(const std::string& path, const std::string& svg) {
    AtomicFileWriter w(path);
    w.write(std::as_bytes(std::span(svg)));
    w.commit();
}

struct LineSeries {
    std::string name;
    std::string color;  // empty: plotColor(index)
    std::string dash;   // SVG stroke-dasharray ("6,4", "2,3"); empty: solid
    std::vector<std::pair<double, double>>
        points;        // drawn in this order; non-finite or (on log axes) non-positive skipped
    bool line = true;  // false: markers only (squares), no line through them
};

struct LinePlot {
    std::string title, xLabel, yLabel;
    bool logX = false, logY = false;
    std::vector<LineSeries> series;
    std::vector<std::pair<std::string, std::pair<double, double>>> rings;  // points circled and labelled

    std::string svg() const {
        const double W = 1100, H = 560, left = 80, right = 400, top = 50, bottom = 60;
        const double pw = W - left - right, ph = H - top - bottom;
        auto usable = [&](double x, double y) {
            return std::isfinite(x) && std::isfinite(y) && (!logX || x > 0) && (!logY || y > 0);
        };
        double x0 = HUGE_VAL, x1 = -HUGE_VAL, y0 = HUGE_VAL, y1 = -HUGE_VAL;
        for (const LineSeries& s : series)
            for (auto [x, y] : s.points)
                if (usable(x, y))
                    x0 = std::min(x0, x), x1 = std::max(x1, x), y0 = std::min(y0, y), y1 = std::max(y1, y);
        if (!(x0 <= x1)) throw Error("plot '" + title + "': no data point to draw");
        auto expand = [](double& lo, double& hi, bool log) {
            if (log) {
                lo /= 1.3, hi *= 1.3;
            } else {
                const double pad = hi > lo ? 0.05 * (hi - lo) : std::max(1.0, std::abs(lo) * 0.1);
                lo -= pad, hi += pad;
            }
        };
        expand(x0, x1, logX);
        expand(y0, y1, logY);
        auto map = [](double v, double lo, double hi, bool log) {
            return log ? (std::log10(v) - std::log10(lo)) / (std::log10(hi) - std::log10(lo)) : (v - lo) / (hi - lo);
        };
        auto px = [&](double x) { return left + pw * map(x, x0, x1, logX); };
        auto py = [&](double y) { return top + ph * (1.0 - map(y, y0, y1, logY)); };
        auto ticks = [](double lo, double hi, bool log) {
            std::vector<double> t;
            if (log) {  // 1, 2, 5 of each decade in the range (1 only, when that leaves at least three)
                std::vector<double> ones;
                for (double d = std::pow(10.0, std::floor(std::log10(lo))); d <= hi; d *= 10) {
                    if (d >= lo) ones.push_back(d);
                    for (double m : {1.0, 2.0, 5.0})
                        if (m * d >= lo && m * d <= hi) t.push_back(m * d);
                }
                if (ones.size() >= 3) t = ones;
            } else {
                t = linearTicks(lo, hi);
            }
            return t;
        };
        std::string o = svgStart(W, H, left, title);
        for (double t : ticks(x0, x1, logX)) {
            o += "<line x1=\"" + svgNum(px(t)) + "\" y1=\"" + svgNum(top) + "\" x2=\"" + svgNum(px(t)) + "\" y2=\"" +
                 svgNum(top + ph) + "\" stroke=\"#ddd\"/>\n";
            o += "<text x=\"" + svgNum(px(t)) + "\" y=\"" + svgNum(top + ph + 16) + "\" text-anchor=\"middle\">" +
                 tickLabel(t) + "</text>\n";
        }
        for (double t : ticks(y0, y1, logY)) {
            o += "<line x1=\"" + svgNum(left) + "\" y1=\"" + svgNum(py(t)) + "\" x2=\"" + svgNum(left + pw) +
                 "\" y2=\"" + svgNum(py(t)) + "\" stroke=\"#ddd\"/>\n";
            o += "<text x=\"" + svgNum(left - 6) + "\" y=\"" + svgNum(py(t) + 4) + "\" text-anchor=\"end\">" +
                 tickLabel(t) + "</text>\n";
        }
        o += "<rect x=\"" + svgNum(left) + "\" y=\"" + svgNum(top) + "\" width=\"" + svgNum(pw) + "\" height=\"" +
             svgNum(ph) + "\" fill=\"none\" stroke=\"#333\"/>\n";
        o += "<text x=\"" + svgNum(left + pw / 2) + "\" y=\"" + svgNum(H - 18) + "\" text-anchor=\"middle\">" +
             svgEscape(xLabel) + "</text>\n";
        o += "<text transform=\"translate(20," + svgNum(top + ph / 2) + ") rotate(-90)\" text-anchor=\"middle\">" +
             svgEscape(yLabel) + "</text>\n";
        for (size_t i = 0; i < series.size(); ++i) {
            const LineSeries& s = series[i];
            const std::string color = s.color.empty() ? plotColor(i) : s.color;
            std::string path;
            for (auto [x, y] : s.points)
                if (usable(x, y)) path += (path.empty() ? "" : " ") + svgNum(px(x)) + "," + svgNum(py(y));
            if (path.empty()) continue;
            if (s.line)
                o += "<polyline points=\"" + path + "\" fill=\"none\" stroke=\"" + color + "\" stroke-width=\"1.8\"" +
                     (s.dash.empty() ? "" : " stroke-dasharray=\"" + s.dash + "\"") + "/>\n";
            auto marker = [&](double cx, double cy) {
                return s.line ? "<circle cx=\"" + svgNum(cx) + "\" cy=\"" + svgNum(cy) + "\" r=\"3\" fill=\"" + color +
                                    "\"/>\n"
                              : "<rect x=\"" + svgNum(cx - 3.5) + "\" y=\"" + svgNum(cy - 3.5) +
                                    "\" width=\"7\" height=\"7\" fill=\"none\" stroke=\"" + color +
                                    "\" stroke-width=\"1.5\"/>\n";
            };
            for (auto [x, y] : s.points)
                if (usable(x, y)) o += marker(px(x), py(y));
            const double ly = top + 10 + 18 * double(i);
            if (s.line)
                o += "<line x1=\"" + svgNum(left + pw + 14) + "\" y1=\"" + svgNum(ly) + "\" x2=\"" +
                     svgNum(left + pw + 40) + "\" y2=\"" + svgNum(ly) + "\" stroke=\"" + color +
                     "\" stroke-width=\"2\"" + (s.dash.empty() ? "" : " stroke-dasharray=\"" + s.dash + "\"") + "/>\n";
            else
                o += marker(left + pw + 27, ly);
            o += "<text x=\"" + svgNum(left + pw + 46) + "\" y=\"" + svgNum(ly + 4) + "\">" + svgEscape(s.name) +
                 "</text>\n";
        }
        for (const auto& [label, xy] : rings)
            if (usable(xy.first, xy.second))
                o += "<circle cx=\"" + svgNum(px(xy.first)) + "\" cy=\"" + svgNum(py(xy.second)) +
                     "\" r=\"8\" fill=\"none\" stroke=\"#333\" stroke-width=\"1.5\"/>\n<text x=\"" +
                     svgNum(px(xy.first) + 10) + "\" y=\"" + svgNum(py(xy.second) - 8) + "\" font-size=\"11\">" +
                     svgEscape(label) + "</text>\n";
        return o + "</svg>\n";
    }
};

// Horizontal bars, one per row, each split into stacked segments (e.g. a frame's stages), with optional
// vertical marker lines (e.g. a target).
struct BarPlot {
    std::string title, xLabel;
    std::vector<std::string> segmentNames;  // legend, one colour each
    struct Row {
        std::string label;
        std::vector<double> segments;  // same order as segmentNames; >= 0
    };
    std::vector<Row> rows;
    std::vector<std::pair<std::string, double>> markers;  // (label, x)

    std::string svg() const {
        const double W = 900, left = 150, right = 190, top = 50, barH = 26, gap = 12;
        const double H = top + double(rows.size()) * (barH + gap) + 60, pw = W - left - right;
        double xMax = 0;
        for (const Row& r : rows) {
            double sum = 0;
            for (double v : r.segments) sum += std::max(0.0, v);
            xMax = std::max(xMax, sum);
        }
        for (const auto& m : markers) xMax = std::max(xMax, m.second);
        if (!(xMax > 0)) throw Error("plot '" + title + "': nothing to draw");
        xMax *= 1.05;
        auto px = [&](double x) { return left + pw * x / xMax; };
        std::string o = svgStart(W, H, left, title);
        const double bottom = top + double(rows.size()) * (barH + gap);
        for (double t : linearTicks(0, xMax)) {
            o += "<line x1=\"" + svgNum(px(t)) + "\" y1=\"" + svgNum(top) + "\" x2=\"" + svgNum(px(t)) + "\" y2=\"" +
                 svgNum(bottom) + "\" stroke=\"#ddd\"/>\n";
            o += "<text x=\"" + svgNum(px(t)) + "\" y=\"" + svgNum(bottom + 16) + "\" text-anchor=\"middle\">" +
                 tickLabel(t) + "</text>\n";
        }
        for (size_t r = 0; r < rows.size(); ++r) {
            const double y = top + double(r) * (barH + gap) + gap / 2;
            o += "<text x=\"" + svgNum(left - 8) + "\" y=\"" + svgNum(y + barH / 2 + 4) + "\" text-anchor=\"end\">" +
                 svgEscape(rows[r].label) + "</text>\n";
            double x = 0;
            for (size_t s = 0; s < rows[r].segments.size(); ++s) {
                const double v = std::max(0.0, rows[r].segments[s]);
                o += "<rect x=\"" + svgNum(px(x)) + "\" y=\"" + svgNum(y) + "\" width=\"" + svgNum(px(x + v) - px(x)) +
                     "\" height=\"" + svgNum(barH) + "\" fill=\"" + plotColor(s) + "\"/>\n";
                x += v;
            }
            o += "<text x=\"" + svgNum(px(x) + 4) + "\" y=\"" + svgNum(y + barH / 2 + 4) + "\">" + tickLabel(x) +
                 "</text>\n";
        }
        for (const auto& [label, x] : markers) {
            o += "<line x1=\"" + svgNum(px(x)) + "\" y1=\"" + svgNum(top - 6) + "\" x2=\"" + svgNum(px(x)) +
                 "\" y2=\"" + svgNum(bottom) + "\" stroke=\"#c00\" stroke-dasharray=\"5,3\"/>\n";
            o += "<text x=\"" + svgNum(px(x) + 3) + "\" y=\"" + svgNum(top - 8) + "\" fill=\"#c00\">" +
                 svgEscape(label) + "</text>\n";
        }
        o += "<text x=\"" + svgNum(left + pw / 2) + "\" y=\"" + svgNum(H - 14) + "\" text-anchor=\"middle\">" +
             svgEscape(xLabel) + "</text>\n";
        for (size_t s = 0; s < segmentNames.size(); ++s) {
            const double ly = top + 18 * double(s);
            o += "<rect x=\"" + svgNum(left + pw + 40) + "\" y=\"" + svgNum(ly) +
                 "\" width=\"14\" height=\"12\" fill=\"" + plotColor(s) + "\"/>\n";
            o += "<text x=\"" + svgNum(left + pw + 60) + "\" y=\"" + svgNum(ly + 10) + "\">" +
                 svgEscape(segmentNames[s]) + "</text>\n";
        }
        return o + "</svg>\n";
    }
};

}  // namespace hc::bench
