#include "heightcast/render/image_io.h"

#include <csetjmp>
#include <cstdio>

#include <png.h>

#include "heightcast/core/atomic_file.h"
#include "heightcast/core/error.h"
#include "heightcast/core/exr.h"

namespace hc::render {

void writePng(const Frame& f, const std::string& path) {
    AtomicPath out(path);
    std::FILE* fp = std::fopen(out.temp().c_str(), "wb");
    if (!fp) throw Error(path + ": cannot create the file");
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
    png_infop info = png ? png_create_info_struct(png) : nullptr;
    if (!png || !info || setjmp(png_jmpbuf(png))) {
        png_destroy_write_struct(&png, &info);
        std::fclose(fp);
        throw Error(path + ": PNG encoding failed");
    }
    png_init_io(png, fp);
    png_set_IHDR(png, info, png_uint_32(f.width), png_uint_32(f.height), 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
                 PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    png_set_sRGB(png, info, PNG_sRGB_INTENT_PERCEPTUAL);
    png_write_info(png, info);
    for (int y = 0; y < f.height; ++y) png_write_row(png, f.rgb.data() + size_t(y) * size_t(f.width) * 3);
    png_write_end(png, nullptr);
    png_destroy_write_struct(&png, &info);
    if (std::fclose(fp) != 0) throw Error(path + ": write failed");
    out.commit();
}

void writeFrameExr(const Frame& f, const std::string& path) {
    std::vector<exr::FloatChannel> channels = {
        {"Z", f.distanceM}, {"P.X", f.posX},        {"P.Y", f.posY},
        {"P.Z", f.posZ},    {"N.X", f.nX},          {"N.Y", f.nY},
        {"N.Z", f.nZ},      {"cascade", f.cascade}, {"water_depth", f.waterDepthM},
        {"wall", f.wall},
    };
    if (!f.colorLayerValue.empty()) channels.push_back({"layer." + f.colorLayer, f.colorLayerValue});
    const exr::Attribute attributes[] = {
        {"heightcast.gridOriginX", f.originWorldX},
        {"heightcast.gridOriginY", f.originWorldY},
    };
    exr::writeFloatImage(path, size_t(f.width), size_t(f.height), channels, attributes);
}

}  // namespace hc::render
