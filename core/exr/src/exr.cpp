#include "heightcast/core/exr.h"

#include <cassert>
#include <climits>

#include <ImfChannelList.h>
#include <ImfDoubleAttribute.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfIntAttribute.h>
#include <ImfOutputFile.h>
#include <ImfStringAttribute.h>

#include "heightcast/core/atomic_file.h"
#include "heightcast/core/error.h"

namespace hc::exr {

void writeFloatImage(const std::string& path, size_t width, size_t height, std::span<const FloatChannel> channels,
                     std::span<const Attribute> attributes) {
    if (width > size_t{INT_MAX} || height > size_t{INT_MAX})
        throw Error(path + ": cannot write OpenEXR: " + std::to_string(width) + " x " + std::to_string(height) +
                    " pixels, more than OpenEXR takes per side");
    AtomicPath out(path);
    try {
        Imf::Header header(static_cast<int>(width), static_cast<int>(height));
        header.compression() = Imf::ZIP_COMPRESSION;
        for (const Attribute& a : attributes) {
            if (const double* d = std::get_if<double>(&a.value))
                header.insert(a.name, Imf::DoubleAttribute(*d));
            else if (const int* i = std::get_if<int>(&a.value))
                header.insert(a.name, Imf::IntAttribute(*i));
            else
                header.insert(a.name, Imf::StringAttribute(std::get<std::string>(a.value)));
        }
        Imf::FrameBuffer fb;
        const size_t xStride = sizeof(float), yStride = sizeof(float) * width;
        for (const FloatChannel& c : channels) {
            assert(!c.name.empty() && c.values.size() == width * height);
            assert(!header.channels().findChannel(c.name) && "channel names must be distinct");
            header.channels().insert(c.name, Imf::Channel(Imf::FLOAT));
            // OpenEXR's Slice takes a mutable pointer for reading and writing alike; an OutputFile only reads it.
            fb.insert(c.name, Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(const_cast<float*>(c.values.data())),
                                         xStride, yStride));
        }
        Imf::OutputFile file(out.temp().c_str(), header);
        file.setFrameBuffer(fb);
        file.writePixels(static_cast<int>(height));
    } catch (const std::exception& e) {
        throw Error(path + ": cannot write OpenEXR: " + e.what());
    }
    out.commit();
}

}  // namespace hc::exr
