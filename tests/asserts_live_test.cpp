// Issue 11: "a Debug build where asserts are live". scripts/test_sanitized.sh builds with HC_SANITIZE=ON, which
// defines HC_REQUIRE_LIVE_ASSERTS for this test: there it fails if NDEBUG compiled the asserts out, and it shows
// that a broken invariant inside the library (a Grid's cells appended out of Morton order) aborts the process,
// so an assert firing anywhere in the suite fails that run. In the Release build it skips, saying so.
#include <gtest/gtest.h>

#include "heightcast/grid/grid.h"

namespace {

TEST(AssertsLive, BrokenInvariantAborts) {
#ifdef NDEBUG
#ifdef HC_REQUIRE_LIVE_ASSERTS
    FAIL() << "this build should have live asserts (HC_SANITIZE), but NDEBUG is defined";
#else
    GTEST_SKIP() << "asserts are compiled out in this build (NDEBUG); scripts/test_sanitized.sh runs them live";
#endif
#else
    GTEST_FLAG_SET(death_test_style, "threadsafe");
    hc::Grid g;
    g.rootLevel = 2;
    g.maxLevel = 2;
    const float v[1] = {100.0f};
    g.appendCell(1, 0, 0, v);
    EXPECT_DEATH(g.appendCell(0, 0, 0, v), "Assertion");  // (0, 0) sorts before (1, 0): out of Morton order
#endif
}

}  // namespace
