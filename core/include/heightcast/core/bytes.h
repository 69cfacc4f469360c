// heightcast/core/bytes.h: little-endian loads and stores of plain values at byte offsets, for the
// file formats (the host is little-endian: checksum.cpp asserts it). memcpy: no alignment assumed.
#pragma once

#include <cstddef>
#include <cstring>
#include <vector>

namespace hc::bytes {

template <typename T>
T load(const std::byte* p) {
    T v;
    std::memcpy(&v, p, sizeof v);
    return v;
}

template <typename T>
void store(std::vector<std::byte>& buf, size_t at, T v) {
    std::memcpy(buf.data() + at, &v, sizeof v);
}

}  // namespace hc::bytes
