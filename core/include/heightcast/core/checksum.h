// heightcast/core/checksum.h: CRC-32 for integrity, a 64-bit hash for identity.
//
// CRC-32 (IEEE 802.3 polynomial, as zlib and PNG) guards every section of our files: it catches
// every burst error of up to 32 bits, so every single flipped byte is detected.
// Hash64 identifies content (cache keys); it is fast and well mixed but not cryptographic.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>

namespace hc {

// CRC-32 of `bytes`, continuing from `crc` (pass 0 to start).
// Carry-less multiplies (PCLMULQDQ) where the CPU has them, else slicing-by-8: the same value.
uint32_t crc32(std::span<const std::byte> bytes, uint32_t crc = 0);
// The same CRC by slicing-by-8 only: the yardstick the fast path is tested against.
uint32_t crc32Portable(std::span<const std::byte> bytes, uint32_t crc = 0);

// The CRC-32 of A followed by B, from crc32(A), crc32(B) and B's length (as zlib's crc32_combine):
// O(log bytesB), no data.
uint32_t crc32Combine(uint32_t crcA, uint32_t crcB, uint64_t bytesB);

// Streaming 64-bit hash: the same bytes give the same value however they are split into update()s.
class Hash64 {
public:
    explicit Hash64(uint64_t seed = 0x6863677269640001ull) : state_(seed) {}
    void update(std::span<const std::byte> bytes);
    template <typename T>
    void updateValue(const T& v) {
        update(std::as_bytes(std::span<const T>(&v, 1)));
    }
    uint64_t digest() const;

    // The running state, so that another process can go on with the same stream (under mpirun each rank hashes its own
    // run of a file's cells, in order: GridFilePart). resume(save()) continues exactly where save() was taken.
    struct State {
        uint64_t state = 0, length = 0, pending = 0, pendingBytes = 0;
    };
    State save() const { return {state_, length_, pending_, uint64_t(pendingBytes_)}; }
    static Hash64 resume(const State& s) {
        Hash64 h(s.state);
        h.length_ = s.length, h.pending_ = s.pending, h.pendingBytes_ = int(s.pendingBytes & 7);
        return h;
    }

private:
    void mixWord(uint64_t w);
    uint64_t state_;
    uint64_t length_ = 0;
    uint64_t pending_ = 0;  // up to 7 bytes not yet mixed
    int pendingBytes_ = 0;
};

}  // namespace hc
