// Where the tests find real rasters: data/ in the repository, then the files unpacked from its zips into the
// build tree (build/data: N00E010.hgt), then ../shared/data beside the repository.
#pragma once

#include <filesystem>
#include <string>

namespace hc::test {

// Path of a raster, or "" if neither directory holds it.
inline std::string dataFile(const std::string& name) {
    for (const char* dir : {HC_DATA_DIR, HC_BUILD_DATA_DIR, HC_SHARED_DATA_DIR}) {
        std::filesystem::path p = std::filesystem::path(dir) / name;
        if (std::filesystem::exists(p)) return p.string();
    }
    return "";
}

}  // namespace hc::test

// Skips the test (saying why) when a raster is absent, e.g. baltoro_srtm.tif on a fresh clone without ../shared.
#define HC_REQUIRE_DATA(var, name)                      \
    const std::string var = ::hc::test::dataFile(name); \
    if (var.empty()) GTEST_SKIP() << name << " is in none of data/, build/data, ../shared/data; skipped"
