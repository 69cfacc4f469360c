// heightcast/grid/morton.h: Morton (Z-order) keys and packed cell codes.
//
// A cell of the quadtree is identified by the integer coordinates (ix, iy) of its south-west
// corner in units of the finest cell size, and by its level (cell size = finest * 2^level).
// Its Morton key interleaves the bits of ix (even bits) and iy (odd bits). Sorting leaves by
// the Morton key of their corner visits them in quadtree depth-first order, and the leaves
// inside any quadtree node form one contiguous run of keys: [nodeKey, nodeKey + 4^level).
//
// A cell code packs key and level into one 64-bit word: code = key << 5 | level. Codes sort like
// keys (leaves never share a corner key), so one sorted array of codes is the whole tree.
#pragma once

#include <cstdint>

namespace hc {

constexpr int kLevelBits = 5;
constexpr int kMaxLevel = 29;      // coarsest level any cell may have
constexpr int kMaxRootLevel = 29;  // the domain is at most 2^29 finest cells per side (2 * 29 + 5 bits)

constexpr uint64_t spreadBits(uint32_t v) {
    uint64_t x = v;
    x = (x | (x << 16)) & 0x0000FFFF0000FFFFull;
    x = (x | (x << 8)) & 0x00FF00FF00FF00FFull;
    x = (x | (x << 4)) & 0x0F0F0F0F0F0F0F0Full;
    x = (x | (x << 2)) & 0x3333333333333333ull;
    x = (x | (x << 1)) & 0x5555555555555555ull;
    return x;
}

constexpr uint32_t compactBits(uint64_t x) {
    x &= 0x5555555555555555ull;
    x = (x | (x >> 1)) & 0x3333333333333333ull;
    x = (x | (x >> 2)) & 0x0F0F0F0F0F0F0F0Full;
    x = (x | (x >> 4)) & 0x00FF00FF00FF00FFull;
    x = (x | (x >> 8)) & 0x0000FFFF0000FFFFull;
    x = (x | (x >> 16)) & 0x00000000FFFFFFFFull;
    return static_cast<uint32_t>(x);
}

constexpr uint64_t mortonEncode(uint32_t ix, uint32_t iy) { return spreadBits(ix) | (spreadBits(iy) << 1); }
constexpr uint32_t mortonX(uint64_t key) { return compactBits(key); }
constexpr uint32_t mortonY(uint64_t key) { return compactBits(key >> 1); }

// Number of finest cells a cell of `level` covers: 4^level (the span of its keys).
constexpr uint64_t mortonSpan(int level) { return uint64_t{1} << (2 * level); }

constexpr uint64_t makeCellCode(uint64_t key, int level) { return (key << kLevelBits) | static_cast<uint64_t>(level); }
constexpr uint64_t codeKey(uint64_t code) { return code >> kLevelBits; }
constexpr int codeLevel(uint64_t code) { return static_cast<int>(code & ((1u << kLevelBits) - 1)); }

static_assert(mortonEncode(1, 0) == 1 && mortonEncode(0, 1) == 2 && mortonEncode(3, 3) == 15);
static_assert(mortonX(mortonEncode(123456, 654321)) == 123456);
static_assert(mortonY(mortonEncode(123456, 654321)) == 654321);
static_assert(2 * kMaxRootLevel + kLevelBits <= 64);

}  // namespace hc
