// influence/src/file_layouts.h: the pieces of the .hci cache (cache_file.cpp) and .hcp pyramid (pyramid_file.cpp)
// files, for writers that place a file's sections and write them in parts: the ranks of mpirun (on_ranks.cpp), each
// writing its share at its place in rank 0's temporary (SectionedFilePart). The whole-object writers
// (writeInfluenceCache, writeSurfacePyramid) are made of the same pieces, so both write the same bytes.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "heightcast/core/sectioned_file.h"
#include "heightcast/influence/kernel.h"
#include "heightcast/influence/pyramid.h"

namespace hc::influence::detail {

// The cache: its format; its sections (OFFSETS, then INDICES) for `cells` cells and `entries` list entries; its header.
const FileFormat& influenceCacheFormat();
std::vector<FileSection> influenceCacheLayout(uint64_t cells, uint64_t entries);
std::vector<std::byte> influenceCacheHeader(uint64_t cells, uint64_t entries, uint64_t longest,
                                            const KernelParams& params, uint64_t structureHash, uint64_t contentHash);

// The pyramid: its format; its sections for a file whose level t holds tiles[t] tiles of sides[t]^2 samples of
// `channels` channels (KEYS, ERRORS, SAMPLES per level: sections 3 t, 3 t + 1, 3 t + 2); the header of p's fields (its
// levels counted, not read).
const FileFormat& pyramidFileFormat();
std::vector<FileSection> pyramidFileLayout(const std::vector<uint64_t>& tiles, const std::vector<int>& sides,
                                           int channels);
std::vector<std::byte> pyramidFileHeader(const SurfacePyramid& p);

}  // namespace hc::influence::detail
