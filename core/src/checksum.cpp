#include "heightcast/core/checksum.h"

#include <array>
#include <bit>
#include <cstring>

#if defined(__x86_64__)
#include <immintrin.h>
#endif

namespace hc {
namespace {

// Slicing-by-8 tables for the reflected IEEE polynomial 0xEDB88320 (eight bytes a step, far faster than one
// table lookup per byte; the grid reader checks every byte it loads).
struct CrcTables {
    std::array<std::array<uint32_t, 256>, 8> t{};
    constexpr CrcTables() {
        for (uint32_t i = 0; i < 256; ++i) {
            uint32_t c = i;
            for (int k = 0; k < 8; ++k) c = (c & 1u) ? (0xEDB88320u ^ (c >> 1)) : (c >> 1);
            t[0][i] = c;
        }
        for (uint32_t i = 0; i < 256; ++i)
            for (int s = 1; s < 8; ++s) t[s][i] = (t[s - 1][i] >> 8) ^ t[0][t[s - 1][i] & 0xFFu];
    }
};
constexpr CrcTables kCrc;

static_assert(std::endian::native == std::endian::little, "heightcast assumes a little-endian host");

// The register after `n` bytes from register c (no inversions): slicing-by-8, then a byte at a time.
uint32_t crcTable(uint32_t c, const unsigned char* p, size_t n) {
    while (n >= 8) {
        uint32_t lo, hi;
        std::memcpy(&lo, p, 4);
        std::memcpy(&hi, p + 4, 4);
        lo ^= c;
        c = kCrc.t[7][lo & 0xFF] ^ kCrc.t[6][(lo >> 8) & 0xFF] ^ kCrc.t[5][(lo >> 16) & 0xFF] ^ kCrc.t[4][lo >> 24] ^
            kCrc.t[3][hi & 0xFF] ^ kCrc.t[2][(hi >> 8) & 0xFF] ^ kCrc.t[1][(hi >> 16) & 0xFF] ^ kCrc.t[0][hi >> 24];
        p += 8;
        n -= 8;
    }
    while (n--) c = kCrc.t[0][(c ^ *p++) & 0xFFu] ^ (c >> 8);
    return c;
}

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define HC_CRC_FOLD 1
// Folding with carry-less multiplies (Intel's "Fast CRC Computation Using PCLMULQDQ"; the constants of Linux's
// crc32-pclmul for this polynomial): four 16-byte lanes are each multiplied forward by x^512 mod P and the next 64
// bytes added, then folded into one lane, which with the tail bytes has the same remainder as the whole message. The
// table finishes those few bytes, so no Barrett reduction is needed. Several times faster than slicing-by-8
// (docs/benchmarks.md): the grid writer checksums every byte it writes.
#define HC_CLMUL __attribute__((target("pclmul,sse4.1")))
// Functions, not lambdas: a lambda does not take its enclosing function's target (a build without -march fails).
HC_CLMUL inline __m128i load(const unsigned char* q) { return _mm_loadu_si128(reinterpret_cast<const __m128i*>(q)); }
HC_CLMUL inline __m128i fold(__m128i x, __m128i k, __m128i next) {
    return _mm_xor_si128(_mm_xor_si128(_mm_clmulepi64_si128(x, k, 0x00), _mm_clmulepi64_si128(x, k, 0x11)), next);
}

HC_CLMUL uint32_t crcFold(uint32_t c, const unsigned char* p, size_t n) {
    const __m128i k1k2 = _mm_set_epi64x(0x1c6e41596, 0x154442bd4);  // x^(512+-32) mod P, reflected
    const __m128i k3k4 = _mm_set_epi64x(0x0ccaa009e, 0x1751997d0);  // x^(128+-32) mod P, reflected
    __m128i x0 = _mm_xor_si128(load(p), _mm_cvtsi32_si128(static_cast<int>(c)));
    __m128i x1 = load(p + 16), x2 = load(p + 32), x3 = load(p + 48);
    p += 64, n -= 64;
    for (; n >= 64; p += 64, n -= 64) {
        x0 = fold(x0, k1k2, load(p));
        x1 = fold(x1, k1k2, load(p + 16));
        x2 = fold(x2, k1k2, load(p + 32));
        x3 = fold(x3, k1k2, load(p + 48));
    }
    __m128i x = fold(fold(fold(x0, k3k4, x1), k3k4, x2), k3k4, x3);
    for (; n >= 16; p += 16, n -= 16) x = fold(x, k3k4, load(p));
    unsigned char rest[16];
    _mm_storeu_si128(reinterpret_cast<__m128i*>(rest), x);
    return crcTable(crcTable(0, rest, 16), p, n);
}

bool hasClmul() {
    static const bool yes = __builtin_cpu_supports("pclmul") && __builtin_cpu_supports("sse4.1");
    return yes;
}
#endif

}  // namespace

uint32_t crc32(std::span<const std::byte> bytes, uint32_t crc) {
    const auto* p = reinterpret_cast<const unsigned char*>(bytes.data());
#ifdef HC_CRC_FOLD
    if (bytes.size() >= 256 && hasClmul()) return ~crcFold(~crc, p, bytes.size());
#endif
    return ~crcTable(~crc, p, bytes.size());
}

uint32_t crc32Portable(std::span<const std::byte> bytes, uint32_t crc) {
    return ~crcTable(~crc, reinterpret_cast<const unsigned char*>(bytes.data()), bytes.size());
}

namespace {

// Polynomial arithmetic modulo the CRC polynomial, in the reflected bit order (zlib 1.2.12's crc32_combine):
// combining shifts crc(A) by 8 * len(B) zero bits, i.e. multiplies it by x^(8 len(B)) mod P.
uint32_t multModP(uint32_t a, uint32_t b) {
    uint32_t m = 1u << 31, p = 0;
    for (;;) {
        if (a & m) {
            p ^= b;
            if ((a & (m - 1)) == 0) break;
        }
        m >>= 1;
        b = (b & 1) ? (b >> 1) ^ 0xEDB88320u : b >> 1;
    }
    return p;
}

// kX2n[k] = x^(2^k) mod P.
struct X2nTable {
    std::array<uint32_t, 32> t{};
    X2nTable() {
        uint32_t p = 1u << 30;  // x^1
        t[0] = p;
        for (size_t n = 1; n < 32; ++n) t[n] = p = multModP(p, p);
    }
};

}  // namespace

uint32_t crc32Combine(uint32_t crcA, uint32_t crcB, uint64_t bytesB) {
    static const X2nTable x2n;
    uint32_t p = 1u << 31;                           // x^0
    for (unsigned k = 3; bytesB; bytesB >>= 1, ++k)  // x^(8 bytesB) = product of x^(2^k) over B's bits, k from 3
        if (bytesB & 1) p = multModP(x2n.t[k & 31], p);
    return multModP(p, crcA) ^ crcB;
}

namespace {
constexpr uint64_t kP1 = 0x9E3779B185EBCA87ull;
constexpr uint64_t kP2 = 0xC2B2AE3D27D4EB4Full;
}  // namespace

void Hash64::mixWord(uint64_t w) {
    state_ ^= std::rotl(w * kP2, 31) * kP1;
    state_ = std::rotl(state_, 27) * kP1 + 0x52DCE729u;
}

void Hash64::update(std::span<const std::byte> bytes) {
    const auto* p = reinterpret_cast<const unsigned char*>(bytes.data());
    size_t n = bytes.size();
    length_ += n;
    while (n > 0 && pendingBytes_ != 0) {  // finish a partial word first
        pending_ |= uint64_t{*p++} << (8 * pendingBytes_);
        --n;
        if (++pendingBytes_ == 8) {
            mixWord(pending_);
            pending_ = 0;
            pendingBytes_ = 0;
        }
    }
    while (n >= 8) {
        uint64_t w;
        std::memcpy(&w, p, 8);
        mixWord(w);
        p += 8;
        n -= 8;
    }
    while (n > 0) {
        pending_ |= uint64_t{*p++} << (8 * pendingBytes_);
        ++pendingBytes_;
        --n;
    }
}

uint64_t Hash64::digest() const {
    uint64_t h = state_;
    if (pendingBytes_ != 0) h ^= std::rotl(pending_ * kP2, 31) * kP1;
    h ^= length_;
    // splitmix64 finaliser: full avalanche
    h ^= h >> 30;
    h *= 0xBF58476D1CE4E5B9ull;
    h ^= h >> 27;
    h *= 0x94D049BB133111EBull;
    h ^= h >> 31;
    return h;
}

}  // namespace hc
