// influence/src/sample_spill.cpp: detail::SampleSpill (on_ranks_parts.h), the temporary file a rank's pyramid samples
// wait in until the pyramid file is written (pyramid_on_ranks.cpp).
#include <fcntl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>

#include "heightcast/core/error.h"
#include "on_ranks_parts.h"

namespace hc::influence {

namespace detail {

namespace {
constexpr size_t kSpillBuffer = size_t{4} << 20;
}

SampleSpill::SampleSpill(const std::string& besidePath) {
    std::filesystem::path dir = std::filesystem::path(besidePath).parent_path();
    where_ = dir.empty() ? std::string(".") : dir.string();
    std::string name = (std::filesystem::path(where_) / ".hc_pyramid_samples.XXXXXX").string();
    fd_ = ::mkstemp(name.data());
    if (fd_ < 0)
        throw Error(where_ + ": cannot create a temporary file for the pyramid's samples: " + std::strerror(errno));
    ::unlink(name.c_str());
    buffer_.reserve(kSpillBuffer);
}

SampleSpill::~SampleSpill() {
    if (mapped_) ::munmap(mapped_, size_t(size_));
    if (fd_ >= 0) ::close(fd_);
}

void SampleSpill::flush() {
    const std::byte* p = buffer_.data();
    size_t left = buffer_.size();
    while (left > 0) {
        const ssize_t n = ::write(fd_, p, left);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0)
            throw Error(where_ + ": cannot write the pyramid's samples to a temporary file (" +
                        std::to_string(size_ >> 20) + " MiB so far): " + std::strerror(n < 0 ? errno : ENOSPC));
        p += n, left -= size_t(n);
    }
    buffer_.clear();
}

uint64_t SampleSpill::append(std::span<const std::byte> bytes) {
    if (mapped_) throw Error("internal: samples appended to a spill already mapped");
    const uint64_t at = size_;
    size_ += bytes.size();
    while (!bytes.empty()) {
        const size_t n = std::min(bytes.size(), kSpillBuffer - buffer_.size());
        buffer_.insert(buffer_.end(), bytes.begin(), bytes.begin() + ptrdiff_t(n));
        bytes = bytes.subspan(n);
        if (buffer_.size() == kSpillBuffer) flush();
    }
    return at;
}

std::span<const std::byte> SampleSpill::map() {
    if (!mapped_) {
        flush();
        std::vector<std::byte>().swap(buffer_);
        if (size_ == 0) return {};
        void* m = ::mmap(nullptr, size_t(size_), PROT_READ, MAP_SHARED, fd_, 0);
        if (m == MAP_FAILED) throw Error(where_ + ": cannot map the pyramid's samples back: " + std::strerror(errno));
        mapped_ = m;
    }
    return {static_cast<const std::byte*>(mapped_), size_t(size_)};
}

void SampleSpill::release(std::span<const std::byte> bytes) const {
    const uintptr_t page = uintptr_t(::sysconf(_SC_PAGESIZE)), a = uintptr_t(bytes.data()),
                    lo = (a + page - 1) / page * page, hi = (a + bytes.size()) / page * page;
    if (hi > lo) ::madvise(reinterpret_cast<void*>(lo), hi - lo, MADV_DONTNEED);
}

}  // namespace detail

}  // namespace hc::influence
