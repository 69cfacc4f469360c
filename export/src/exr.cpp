#include <cmath>

#include <ImfChannelList.h>
#include <ImfDoubleAttribute.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfOutputFile.h>
#include <ImfStringAttribute.h>

#include "heightcast/export/export.h"
#include "heightcast/core/atomic_file.h"
#include "heightcast/core/error.h"

namespace hc::exporting {

void writeExr(const SampledRaster& r, const std::string& path) {
    AtomicPath out(path);
    std::vector<float> coverage(r.values.size());
    for (size_t i = 0; i < r.values.size(); ++i) coverage[i] = std::isnan(r.values[i]) ? 0.0f : 1.0f;
    try {
        Imf::Header header(static_cast<int>(r.width), static_cast<int>(r.height));
        header.compression() = Imf::ZIP_COMPRESSION;
        header.channels().insert(r.layer, Imf::Channel(Imf::FLOAT));
        header.channels().insert("A", Imf::Channel(Imf::FLOAT));
        header.insert("heightcast.originX", Imf::DoubleAttribute(r.originWorldX));
        header.insert("heightcast.originY", Imf::DoubleAttribute(r.originWorldY));
        header.insert("heightcast.westX", Imf::DoubleAttribute(r.westWorld));
        header.insert("heightcast.northY", Imf::DoubleAttribute(r.northWorld));
        header.insert("heightcast.pixelSizeM", Imf::DoubleAttribute(r.pixelSizeM));
        header.insert("heightcast.crsWkt", Imf::StringAttribute(r.crsWkt));
        header.insert("heightcast.layer", Imf::StringAttribute(r.layer));
        header.insert("heightcast.units", Imf::StringAttribute(r.units));
        Imf::OutputFile file(out.temp().c_str(), header);
        Imf::FrameBuffer fb;
        const size_t xs = sizeof(float), ys = sizeof(float) * r.width;
        fb.insert(r.layer, Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(const_cast<float*>(r.values.data())), xs, ys));
        fb.insert("A", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(coverage.data()), xs, ys));
        file.setFrameBuffer(fb);
        file.writePixels(static_cast<int>(r.height));
    } catch (const std::exception& e) {
        throw Error(path + ": cannot write OpenEXR: " + e.what());
    }
    out.commit();
}

}  // namespace hc::exporting
