// hc_hostile_craft: writes the crafted files of the CLI tests in hostile_files.cmake (issue 11), every
// checksum valid (tests/hostile_files.h says how each one fooled the old readers).
//   hc_hostile_craft grid-cells IN.hcg OUT.hcg COUNT     empty CELLS/LAYER sections, COUNT cells declared
//   hc_hostile_craft cache-entries IN.hci OUT.hci COUNT  empty INDICES, COUNT entries declared
//   hc_hostile_craft cache-past-end IN.hci OUT.hci N     the first list ends N entries past the entry count
#include <cstdio>
#include <exception>
#include <string>

#include "../hostile_files.h"

int main(int argc, char** argv) {
    if (argc != 5) {
        std::fprintf(stderr, "usage: hc_hostile_craft grid-cells|cache-entries|cache-past-end IN OUT COUNT\n");
        return 2;
    }
    try {
        const std::string what = argv[1], in = argv[2], out = argv[3];
        const uint64_t count = std::stoull(argv[4]);
        if (what == "grid-cells")
            hc::hostile::gridWithEmptySections(in, out, count);
        else if (what == "cache-entries")
            hc::hostile::cacheWithEntryCount(in, out, count);
        else if (what == "cache-past-end")
            hc::hostile::cacheWithListPastTheEnd(in, out, count);
        else
            throw std::runtime_error("unknown craft " + what);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "hc_hostile_craft: %s\n", e.what());
        return 1;
    }
    return 0;
}
