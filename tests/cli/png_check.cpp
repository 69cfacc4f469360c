// png_check: asserts that a PNG shows a picture, not a blank window: the CLI tests' check of hc-view's
// screenshots. Reads the file with libpng (8-bit RGB or RGBA), prints what it found and exits 0 only if
//   - the image has more than MIN_COLOURS distinct colours (default 50: a blank or single-colour window has 1,
//     the HUD's text adds a handful; shaded terrain has thousands), and
//   - in the central third of the image at least half the pixels differ (sum of |dR|+|dG|+|dB| > 24) from the
//     top-right corner pixel, which is sky in the overview view (the terrain is centred and seen from above),
//     so the terrain, not the sky or the clear colour, fills the centre.
//
//   png_check FILE.png [MIN_COLOURS]
#include <png.h>

#include <cstdio>
#include <cstdlib>
#include <set>
#include <vector>

int main(int argc, char** argv) {
    if (argc < 2) {
        std::fprintf(stderr, "usage: png_check FILE.png [MIN_COLOURS]\n");
        return 2;
    }
    const long minColours = argc > 2 ? std::atol(argv[2]) : 50;
    png_image img{};
    img.version = PNG_IMAGE_VERSION;
    if (!png_image_begin_read_from_file(&img, argv[1])) {
        std::fprintf(stderr, "png_check: %s: cannot read as PNG: %s\n", argv[1], img.message);
        return 1;
    }
    img.format = PNG_FORMAT_RGB;
    std::vector<unsigned char> px(PNG_IMAGE_SIZE(img));
    if (!png_image_finish_read(&img, nullptr, px.data(), 0, nullptr)) {
        std::fprintf(stderr, "png_check: %s: cannot decode: %s\n", argv[1], img.message);
        return 1;
    }
    const int w = int(img.width), h = int(img.height);
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
