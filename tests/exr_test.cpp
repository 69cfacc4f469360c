// hc::exr::writeFloatImage (core/exr), the one OpenEXR writer, read back with OpenEXR itself: every channel
// bit for bit, every typed attribute, ZIP compression; a failed write names the file and leaves nothing.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include <ImfChannelList.h>
#include <ImfDoubleAttribute.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfIntAttribute.h>
#include <ImfStringAttribute.h>

#include "heightcast/core/error.h"
#include "heightcast/core/exr.h"
#include "temp_dir.h"

namespace {

namespace fs = std::filesystem;

class Exr : public hc::test::TempDirTest {
protected:
    Exr() : TempDirTest("hc_exr_") {}
};

TEST_F(Exr, ChannelsAndTypedAttributesReadBack) {
    const fs::path& dir = dir_;
    const size_t width = 3, height = 2;
    const float inf = std::numeric_limits<float>::infinity(), nan = std::numeric_limits<float>::quiet_NaN();
    // Row 0 first; the extremes a float channel must keep: NaN, infinity, negative zero, the smallest subnormal.
    const std::vector<float> z = {1.5f, -0.0f, inf, 5.0e6f, std::numeric_limits<float>::denorm_min(), nan};
    const std::vector<float> a = {0, 1, 2, 3, 4, 5};
    const hc::exr::FloatChannel channels[] = {{"Z", z}, {"A", a}};
    const hc::exr::Attribute attributes[] = {
        {"test.double", 5189000.5}, {"test.int", -7}, {"test.string", std::string("PROJCRS[\"x\"]")}};
    const std::string path = (dir / "t.exr").string();
    hc::exr::writeFloatImage(path, width, height, channels, attributes);

    Imf::InputFile in(path.c_str());
    const Imf::Header& h = in.header();
    EXPECT_EQ(h.compression(), Imf::ZIP_COMPRESSION);
    EXPECT_EQ(h.typedAttribute<Imf::DoubleAttribute>("test.double").value(), 5189000.5);
    EXPECT_EQ(h.typedAttribute<Imf::IntAttribute>("test.int").value(), -7);
    EXPECT_EQ(h.typedAttribute<Imf::StringAttribute>("test.string").value(), "PROJCRS[\"x\"]");
    const Imath::Box2i dw = h.dataWindow();
    ASSERT_EQ(dw.max.x - dw.min.x + 1, int(width));
    ASSERT_EQ(dw.max.y - dw.min.y + 1, int(height));
    int count = 0;
    for (auto c = h.channels().begin(); c != h.channels().end(); ++c, ++count)
        EXPECT_EQ(c.channel().type, Imf::FLOAT) << c.name();
    EXPECT_EQ(count, 2);
    std::vector<float> zBack(z.size(), 42.0f), aBack(a.size(), 42.0f);
    Imf::FrameBuffer fb;
    fb.insert("Z", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(zBack.data()), 4, 4 * width));
    fb.insert("A", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(aBack.data()), 4, 4 * width));
    in.setFrameBuffer(fb);
    in.readPixels(dw.min.y, dw.max.y);
    for (size_t i = 0; i < z.size(); ++i) {
        EXPECT_EQ(std::signbit(zBack[i]), std::signbit(z[i])) << i;
        if (std::isnan(z[i]))
            EXPECT_TRUE(std::isnan(zBack[i])) << i;
        else
            EXPECT_EQ(zBack[i], z[i]) << i;
        EXPECT_EQ(aBack[i], a[i]) << i;
    }
    EXPECT_EQ(std::distance(fs::directory_iterator(dir), fs::directory_iterator()), 1)
        << "a temporary was left beside t.exr";
}

TEST_F(Exr, FailedWriteNamesTheFileAndLeavesNothing) {
    const fs::path& dir = dir_;
    const std::vector<float> v(4, 1.0f);
    const hc::exr::FloatChannel channels[] = {{"Z", v}};
    const std::string path = (dir / "missing_dir" / "x.exr").string();
    try {
        hc::exr::writeFloatImage(path, 2, 2, channels, {});
        FAIL() << "a write into a missing directory succeeded";
    } catch (const hc::Error& e) {
        EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    }
    EXPECT_TRUE(fs::is_empty(dir));
}

}  // namespace
