// fuzz_bookmarks: hc-view's bookmarks JSON reader (hc::view::bookmarksFromJson) on any text. Only hc::Error
// may come out: any other exception, crash or sanitizer report is a finding. What it accepts must survive
// a round trip through bookmarksToJson unchanged.
#include <string_view>

#include "heightcast/core/error.h"
#include "heightcast/support/view_support.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    try {
        const hc::view::Bookmarks b =
            hc::view::bookmarksFromJson(std::string_view(reinterpret_cast<const char*>(data), size));
        const std::string again = hc::view::bookmarksToJson(b);
        if (hc::view::bookmarksToJson(hc::view::bookmarksFromJson(again)) != again) __builtin_trap();
    } catch (const hc::Error&) {
    }
    return 0;
}
