// influence/src/pyramid_storage.h: what lies behind a SurfacePyramid's spans: vectors it built, or the
// mapping of the file it was read from.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "heightcast/core/sectioned_file.h"
#include "heightcast/influence/pyramid.h"

namespace hc::influence {

struct SurfacePyramid::Storage {
    std::vector<std::vector<uint64_t>> keys;    // per level (built)
    std::vector<std::vector<float>> samples;    // per level (built)
    std::vector<std::vector<float>> errors;     // per level (built)
    std::shared_ptr<const MappedFile> mapping;  // read
};

}  // namespace hc::influence
