// render/gl/src/backend_atlas.cpp: the GL backend's atlases (TileAtlas: pyramid tiles resident on the GPU from frame
// to frame, docs/design.md section 4), and out of core the tiles a frame copies texels from (atlas.comp) and the blocks
// it interpolates from level 0's tiles (interpolate.comp) placed in them, or filled on the CPU where no slot is left.
#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <string>

#include "backend_internal.h"
#include "heightcast/core/error.h"

namespace hc::render {
namespace gl {

void TileAtlas::open(size_t bytes, size_t channelPlanes) {
    if (capacity) return;
    planes = channelPlanes;
    const size_t slotBytes = planes * size_t(gpu::kAtlasPlane) * sizeof(float);
    capacity = uint32_t(std::min<size_t>(bytes / slotBytes, size_t{1} << 24));
    if (limit) capacity = std::min(capacity, limit);
    buffer.reserve(size_t(capacity) * slotBytes);
    tileIn.assign(capacity, nullptr), usedIn.assign(capacity, 0), validRows.assign(capacity, {});
}

uint32_t TileAtlas::slot(const float* tile, size_t plane) {
    if (const auto it = slotOf.find(tile); it != slotOf.end()) {
        if (usedIn[it->second] != frame) usedIn[it->second] = frame, ++usedNow;
        return it->second;
    }
    if (usedNow >= capacity) return kNone;
    while (usedIn[hand] == frame && tileIn[hand]) hand = (hand + 1) % capacity;
    const uint32_t s = hand;
    hand = (hand + 1) % capacity;
    if (tileIn[s]) slotOf.erase(tileIn[s]);
    tileIn[s] = tile, usedIn[s] = frame, ++usedNow;
    slotOf.emplace(tile, s);
    const size_t at = staging.size();
    staging.resize(at + planes * size_t(gpu::kAtlasPlane), 0.0f);
    for (size_t c = 0; c < planes; ++c)
        std::copy_n(tile + c * plane, plane, &staging[at + c * size_t(gpu::kAtlasPlane)]);
    stagedSlots.push_back(s);
    const size_t side = sideOf(plane);
    validRows[s] = {};
    for (size_t r = 0; r < side; ++r)
        for (size_t c = 0; c < side; ++c) validRows[s][r] |= uint16_t(!std::isnan(tile[r * side + c]) << c);
    return s;
}

void TileAtlas::upload() {
    const size_t slotFloats = planes * size_t(gpu::kAtlasPlane);
    for (size_t a = 0; a < stagedSlots.size();) {
        size_t b = a + 1;
        while (b < stagedSlots.size() && stagedSlots[b] == stagedSlots[b - 1] + 1) ++b;
        buffer.upload(&staging[a * slotFloats], (b - a) * slotFloats * sizeof(float),
                      size_t(stagedSlots[a]) * slotFloats * sizeof(float));
        a = b;
    }
    uploadedTiles += stagedSlots.size(), uploadedBytes += staging.size() * sizeof(float);
    staging.clear(), stagedSlots.clear();
}

void TileAtlas::release() {
    buffer.release();
    capacity = 0, hand = 0, usedNow = 0;
    slotOf.clear(), tileIn.clear(), usedIn.clear(), validRows.clear();
}

}  // namespace gl

// Cascade k's tiles to copy texels from (detail::PyramidTiles) as atlas.comp's, uploaded into the atlas where not
// resident. The texels of a tile that finds no slot (this frame uses every one) are copied here, into `tex`, and
// their row's RowFill span widened to hold them, so that they go up with the CPU's texels. Returns the texels copied
// with a surface (approximate() leaves them to be counted here: counting them there read every tile's samples, which
// the CPU otherwise never touches once the tile is resident; 40 % of copyPyramidTexels on llvmpipe).
// The rows of the tiles placed widen [rowLo, rowHi] (their spans go up for atlas.comp).
uint64_t GlRenderer::Impl::placeTiles(size_t k, detail::CascadeTextures& tex, detail::CascadeFill& fill, float minDepth,
                                      int& rowLo, int& rowHi) {
    const detail::PyramidTiles& p = fill.tiles;
    if (p.side == 0) return 0;
    uint64_t copied = 0;
    openAtlases();
    const size_t n = size_t(tex.terrain.n), side = size_t(p.side);
    const int shift = std::countr_zero(side);
    if (n + side >= 32768)  // atlas.comp's tiles hold their first texel's i and j in 16 bits each
        throw Error("the GL backend copies the pyramid's texels into cascades of under 32752 texels a side, not " +
                    std::to_string(n));
    for (size_t e = 0; e < p.tile.size(); ++e) {
        const float* tile = p.tile[e];
        if (!tile) continue;
        const float* water = p.water[e];
        const uint16_t* rows = &p.copied[e * side];
        // The texel of the tile's first sample (it may lie outside the cascade: the tile's samples there are not
        // marked).
        const int64_t i0 = int64_t(e % size_t(p.width)) * int64_t(side) - p.originI,
                      j0 = int64_t(e / size_t(p.width)) * int64_t(side) - p.originJ;
        const uint32_t slot = terrainAtlas.slot(tile, p.plane);
        const uint32_t waterSlot =
            water && slot != TileAtlas::kNone ? waterAtlas.slot(water, p.plane) : TileAtlas::kNone;
        if (slot != TileAtlas::kNone && (!water || waterSlot != TileAtlas::kNone)) {
            // The first texel's i and j in 16 bits each (offset by 2^15: a tile may begin left of or below texel 0).
            atlasTiles.insert(atlasTiles.end(),
                              {uint32_t(k) | uint32_t(shift) << 4, uint32_t(i0 + 32768) | uint32_t(j0 + 32768) << 16,
                               slot, water ? waterSlot : TileAtlas::kNone});
            rowLo = std::min(rowLo, int(std::max<int64_t>(j0, 0))),
            rowHi = std::max(rowHi, int(std::min(j0 + int64_t(side) - 1, int64_t(n) - 1)));
            for (size_t r = 0; r < side; ++r) atlasTexels += uint64_t(std::popcount(unsigned(rows[r])));
            copied += uint64_t(terrainAtlas.validIn(slot, rows, side));
            continue;
        }
        for (size_t r = 0; r < side; ++r) {
            const size_t j = size_t(j0 + int64_t(r));
            for (unsigned bits = rows[r]; bits;) {  // each run of marked samples, split where it leaves a span
                const int c0 = std::countr_zero(bits);
                int c1 = c0 + std::countr_one(bits >> c0) - 1;
                const int i = int(i0) + c0;
                const detail::RowFill& s = p.spans[j];
                const int span = i >= s.a.first && i <= s.a.last ? 0 : 1;
                c1 = std::min(c1, s.span(span).last - int(i0));
                bits &= ~((2u << c1) - (1u << c0));
                const size_t at = j * n + size_t(i), sample = (r << shift) + size_t(c0);
                const int count = c1 - c0 + 1;
                copied += uint64_t(detail::copySamples(tile + sample, water ? water + sample : nullptr, p.plane, count,
                                                       minDepth, &tex.terrain.h[at], water ? &tex.depth[at] : nullptr,
                                                       water ? &tex.water.h[at] : nullptr));
                detail::widenSpan(fill.rows[j], span, i, i + count - 1);
            }
        }
    }
    terrainAtlas.upload(), waterAtlas.upload();
    return copied;
}

// The atlases take their storage at the first frame that copies from the pyramid: up to 96 MiB each.
void GlRenderer::Impl::openAtlases() {
    const size_t atlasBytes = std::min<size_t>(size_t(maxStorageBlock), size_t(96) << 20);
    terrainAtlas.open(atlasBytes, 1);
    if (scene->hasWater()) waterAtlas.open(atlasBytes, 2);
}

// Cascade k's blocks of texels to interpolate from level 0's tiles (detail::PyramidTiles::Block) as
// interpolate.comp's, their tiles uploaded into the atlas where not resident; their rows widen [rowLo, rowHi]. A block
// whose tiles do not all find a slot (this frame uses every one) is interpolated here, into `tex`, and its rows'
// RowFill spans widened to hold it, so that it goes up with the CPU's texels.
void GlRenderer::Impl::placeBlocks(size_t k, const Cascade& c, detail::CascadeTextures& tex, detail::CascadeFill& fill,
                                   double waterMinDepthM, int& rowLo, int& rowHi) {
    const detail::PyramidTiles& p = fill.tiles;
    if (p.blocks.empty()) return;
    openAtlases();
    const int n = tex.terrain.n, side = p.levelSide << p.up;
    if (n + side >= 32768)  // interpolate.comp's blocks hold their first texel's i and j in 16 bits each
        throw Error("the GL backend interpolates the pyramid's texels into cascades of under " +
                    std::to_string(32768 - side) + " texels a side, not " + std::to_string(n));
    for (const detail::PyramidTiles::Block& b : p.blocks) {
        std::array<uint32_t, gpu::kAtlasBlockUints> e;
        e[0] = uint32_t(k) | uint32_t(p.up) << 4 | uint32_t(std::countr_zero(unsigned(p.levelSide))) << 8;
        e[1] = uint32_t(b.i0 + 32768) | uint32_t(b.j0 + 32768) << 16;
        bool placed = true;
        for (size_t q = 0; q < 9 && placed; ++q) {
            e[2 + q] = terrainAtlas.slot(b.tile[q], p.levelPlane);
            e[11 + q] = b.water[q] && e[2 + q] != TileAtlas::kNone ? waterAtlas.slot(b.water[q], p.levelPlane)
                                                                   : TileAtlas::kNone;
            placed = e[2 + q] != TileAtlas::kNone && (!b.water[q] || e[11 + q] != TileAtlas::kNone);
        }
        if (!placed) {
            detail::interpolateBlock(*scene, c, p, b, waterMinDepthM, tex, fill.rows);
            continue;
        }
        atlasBlocks.insert(atlasBlocks.end(), e.begin(), e.end());
        const int j0 = int(b.j0);
        rowLo = std::min(rowLo, std::max(j0, 0)), rowHi = std::max(rowHi, std::min(j0 + side - 1, n - 1));
        // The texels interpolate.comp writes.
        detail::forEachBlockRun(p, b, n, [&](int, int lo, int hi, int) { atlasInterpolated += uint64_t(hi - lo + 1); });
    }
    terrainAtlas.upload(), waterAtlas.upload();
}

}  // namespace hc::render
