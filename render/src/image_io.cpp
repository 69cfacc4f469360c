#include "heightcast/render/image_io.h"

#include <csetjmp>
#include <cstdio>

#include <ImfChannelList.h>
#include <ImfDoubleAttribute.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfOutputFile.h>
#include <png.h>

#include "heightcast/core/atomic_file.h"
#include "heightcast/core/error.h"

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
    AtomicPath out(path);
    try {
        Imf::Header header(f.width, f.height);
        header.compression() = Imf::ZIP_COMPRESSION;
        header.insert("heightcast.originX", Imf::DoubleAttribute(f.originWorldX));
        header.insert("heightcast.originY", Imf::DoubleAttribute(f.originWorldY));
        Imf::FrameBuffer fb;
        const size_t xs = sizeof(float), ys = sizeof(float) * size_t(f.width);
        auto add = [&](const char* name, const std::vector<float>& v) {
            header.channels().insert(name, Imf::Channel(Imf::FLOAT));
            fb.insert(name, Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(const_cast<float*>(v.data())), xs, ys));
        };
        add("Z", f.distanceM);
        add("P.X", f.posX);
        add("P.Y", f.posY);
        add("P.Z", f.posZ);
        add("N.X", f.nX);
        add("N.Y", f.nY);
        add("N.Z", f.nZ);
        add("cascade", f.cascade);
        add("water_depth", f.waterDepthM);
        add("wall", f.wall);
        Imf::OutputFile file(out.temp().c_str(), header);
        file.setFrameBuffer(fb);
        file.writePixels(f.height);
    } catch (const std::exception& e) {
        throw Error(path + ": cannot write OpenEXR: " + e.what());
    }
    out.commit();
}

}  // namespace hc::render
