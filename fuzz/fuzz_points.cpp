// fuzz_points: hc-probe's points CSV reader (hc::cli::parsePointsCsv) on any text. Only hc::Error may come
// out: any other exception, crash or sanitizer report is a finding; every point it accepts is finite.
#include <cmath>
#include <string_view>

#include "heightcast/support/cli.h"
#include "heightcast/core/error.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    try {
        for (const auto& p :
             hc::cli::parsePointsCsv(std::string_view(reinterpret_cast<const char*>(data), size), "points.csv"))
            if (!std::isfinite(p[0]) || !std::isfinite(p[1])) __builtin_trap();
    } catch (const hc::Error&) {
    }
    return 0;
}
