// png_check: asserts that a PNG shows a picture, not a blank window: the CLI tests' check of hc-view's
// screenshots. Reads the file with libpng (8-bit RGB or RGBA), prints what it found and exits 0 only if
//   - the image has more than MIN_COLOURS distinct colours (default 50: a blank or single-colour window has 1,
//     the HUD's text adds a handful; shaded terrain has thousands), and
//   - in the central third of the image at least half the pixels differ (sum of |dR|+|dG|+|dB| > 24) from the
//     top-right corner pixel, which is sky in the overview view (the terrain is centred and seen from above),
//     so the terrain, not the sky or the clear colour, fills the centre.
//
//   png_check FILE.png [MIN_COLOURS]
//
// With --same-below ROW, asserts instead that two PNGs of the same size hold the same bytes in every row from ROW down
// (the picture under hc-view's HUD, whose timings differ from run to run), printing how many pixels differ:
//
//   png_check --same-below ROW A.png B.png
#include <png.h>

#include <cstdio>
#include <cstdlib>
#include <set>
#include <string>
#include <vector>

namespace {

// The PNG's pixels as 8-bit RGB, or false (saying why on stderr).
bool readRgb(const char* path, int& w, int& h, std::vector<unsigned char>& px) {
    png_image img{};
    img.version = PNG_IMAGE_VERSION;
    if (!png_image_begin_read_from_file(&img, path)) {
        std::fprintf(stderr, "png_check: %s: cannot read as PNG: %s\n", path, img.message);
        return false;
    }
    img.format = PNG_FORMAT_RGB;
    px.resize(PNG_IMAGE_SIZE(img));
    if (!png_image_finish_read(&img, nullptr, px.data(), 0, nullptr)) {
        std::fprintf(stderr, "png_check: %s: cannot decode: %s\n", path, img.message);
        return false;
    }
    w = int(img.width), h = int(img.height);
    return true;
}

int sameBelow(int row, const char* a, const char* b) {
    int wa = 0, ha = 0, wb = 0, hb = 0;
    std::vector<unsigned char> pa, pb;
    if (!readRgb(a, wa, ha, pa) || !readRgb(b, wb, hb, pb)) return 1;
    if (wa != wb || ha != hb || row < 0 || row >= ha) {
        std::printf("png_check: FAIL: %s is %d x %d, %s %d x %d (rows from %d compared)\n", a, wa, ha, b, wb, hb, row);
        return 1;
    }
    long differ = 0;
    for (size_t i = size_t(row) * size_t(wa); i < size_t(wa) * size_t(ha); ++i)
        if (pa[3 * i] != pb[3 * i] || pa[3 * i + 1] != pb[3 * i + 1] || pa[3 * i + 2] != pb[3 * i + 2]) ++differ;
    std::printf("png_check: %s and %s: %ld of %ld pixels differ from row %d down\n", a, b, differ,
                long(wa) * long(ha - row), row);
    return differ == 0 ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
    if (argc == 5 && std::string(argv[1]) == "--same-below") return sameBelow(std::atoi(argv[2]), argv[3], argv[4]);
    if (argc < 2) {
        std::fprintf(stderr, "usage: png_check FILE.png [MIN_COLOURS] | png_check --same-below ROW A.png B.png\n");
        return 2;
    }
    const long minColours = argc > 2 ? std::atol(argv[2]) : 50;
    int w = 0, h = 0;
    std::vector<unsigned char> px;
    if (!readRgb(argv[1], w, h, px)) return 1;
    auto at = [&](int x, int y) { return &px[(size_t(y) * size_t(w) + size_t(x)) * 3]; };
    std::set<unsigned> colours;
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const unsigned char* p = at(x, y);
            colours.insert(unsigned(p[0]) << 16 | unsigned(p[1]) << 8 | p[2]);
        }
    const unsigned char* sky = at(w - 1, 0);
    long centre = 0, differs = 0;
    for (int y = h / 3; y < 2 * h / 3; ++y)
        for (int x = w / 3; x < 2 * w / 3; ++x, ++centre) {
            const unsigned char* p = at(x, y);
            if (std::abs(p[0] - sky[0]) + std::abs(p[1] - sky[1]) + std::abs(p[2] - sky[2]) > 24) ++differs;
        }
    std::printf(
        "png_check: %s: %d x %d, %zu distinct colours, %.1f %% of the centre differs from the corner colour %d,%d,%d\n",
        argv[1], w, h, colours.size(), centre ? 100.0 * double(differs) / double(centre) : 0.0, sky[0], sky[1], sky[2]);
    bool ok = true;
    if (long(colours.size()) <= minColours)
        std::printf("png_check: FAIL: no more than %ld distinct colours: blank?\n", minColours), ok = false;
    if (centre == 0 || differs * 2 < centre)
        std::printf("png_check: FAIL: the centre is mostly the corner (sky) colour\n"), ok = false;
    return ok ? 0 : 1;
}
