// Where the tests find real rasters: data/ in the repository, then ../shared/data beside it.
#pragma once

#include <filesystem>
#include <string>

namespace hc::test {

// Path of a raster, or "" if neither directory holds it.
inline std::string dataFile(const std::string& name) {
    for (const char* dir : {HC_DATA_DIR, HC_SHARED_DATA_DIR}) {
        std::filesystem::path p = std::filesystem::path(dir) / name;
        if (std::filesystem::exists(p)) return p.string();
    }
    return "";
}

}  // namespace hc::test

// Skips the test (saying why) when a raster is absent, e.g. N00E010.hgt on a fresh clone.
#define HC_REQUIRE_DATA(var, name)                                                              \
    const std::string var = ::hc::test::dataFile(name);                                         \
    if (var.empty()) GTEST_SKIP() << name << " is in neither data/ nor ../shared/data; skipped"
