#include "heightcast/core/atomic_file.h"

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <algorithm>
#include <filesystem>
#include <future>
#include <vector>

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include "heightcast/core/error.h"

namespace hc {

namespace {

// Every temporary is TARGET.tmp.XXXXXX: never the target's name nor its extension, so neither a later run nor a
// glob such as *.png takes it for output. Its writer holds an exclusive flock on it for as long as it lives; the
// kernel drops the lock when the process dies, SIGKILL included. So a temporary of the same target that nobody
// locks was left by a killed run and is removed here, before we make ours: killed runs do not pile up half-written
// files (issue 11, kill -9 during writes). Two live runs writing the same target keep each other's temporaries.
int createLockedTemporary(const std::string& target, std::string& tempPath) {
    namespace fs = std::filesystem;
    const fs::path t(target);
    const fs::path dir = t.parent_path().empty() ? fs::path(".") : t.parent_path();
    const std::string prefix = t.filename().string() + ".tmp.";
    std::error_code ec;
    for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
        const std::string name = it->path().filename().string();
        if (name.size() != prefix.size() + 6 || name.compare(0, prefix.size(), prefix) != 0) continue;
        int fd = ::open(it->path().c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW);
        if (fd < 0) continue;
        if (::flock(fd, LOCK_EX | LOCK_NB) == 0) ::unlink(it->path().c_str());
        ::close(fd);
    }
    // mkstemp in the target's directory: rename() is atomic only within one file system.
    std::string pattern = target + ".tmp.XXXXXX";
    std::vector<char> buf(pattern.begin(), pattern.end());
    buf.push_back('\0');
    int fd = mkstemp(buf.data());
    if (fd < 0) throw Error(target + ": cannot create a file there: " + std::strerror(errno));
    ::flock(fd, LOCK_EX | LOCK_NB);  // cannot fail: the file is new and ours
    ::fchmod(fd, 0644);
    tempPath = buf.data();
    return fd;
}

}  // namespace

AtomicFileWriter::AtomicFileWriter(std::string path) : path_(std::move(path)) {
    fd_ = createLockedTemporary(path_, tempPath_);
}

namespace {
constexpr size_t kDirectAlign = 4096;           // O_DIRECT's alignment of offsets, sizes and memory on any device
constexpr size_t kRunBuffer = size_t{4} << 20;  // a run's staging buffer: one O_DIRECT write
}  // namespace

// A run's two staging buffers: one fills while the other is written on a thread of its own (the write of a full one
// takes as long as filling it), so the caller never waits on the disk unless it outruns it.
struct AtomicFileWriter::Run {
    uint64_t at = 0;  // the file offset of fill[0]: aligned
    size_t used = 0;
    bool open = false;
    std::byte* fill = nullptr;
    std::byte* spare = nullptr;
    std::future<void> writing;  // of `spare`
    ~Run() {
        if (writing.valid()) writing.wait();
        std::free(fill);
        std::free(spare);
    }
};

AtomicFileWriter::~AtomicFileWriter() {
    runs_.clear();  // their writes finished
    if (directOpened_ >= 0) ::close(directOpened_);
    if (fd_ >= 0) ::close(fd_);
    if (!committed_ && !tempPath_.empty()) std::remove(tempPath_.c_str());
}

void AtomicFileWriter::fail(const std::string& what) {
    int err = errno;
    throw Error(path_ + ": " + what + ": " + std::strerror(err));
}

void AtomicFileWriter::writeAt(uint64_t offset, std::span<const std::byte> bytes) {
    const std::byte* p = bytes.data();
    size_t left = bytes.size();
    while (left > 0) {
        ssize_t n = ::pwrite(fd_, p, left, static_cast<off_t>(offset));
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) fail("write failed");
        p += n;
        left -= static_cast<size_t>(n);
        offset += static_cast<uint64_t>(n);
    }
    startWriteBack(bytes.size());
}

void AtomicFileWriter::startWriteBack(size_t written) {
    // The kernel starts writing dirty pages back only past a share of the memory (10 % by default: gigabytes) or after
    // 30 s, so a file of a few GB written in seconds would all wait for commit()'s fsync: seconds of nothing but the
    // disk at the end. Asking for the write-back every 64 MiB (asynchronous: the pages stay cached) lets the disk work
    // while we compute, and keeps the dirty pages few.
    unflushed_ += written;
    if (unflushed_ < (size_t{16} << 20)) return;
    unflushed_ = 0;
#ifdef __linux__
    ::sync_file_range(fd_, 0, 0, SYNC_FILE_RANGE_WRITE);  // a hint: its failure changes nothing
#endif
}

void AtomicFileWriter::writeRun(size_t run, uint64_t offset, std::span<const std::byte> bytes) {
    if (!directTried_) {
        directTried_ = true;
#ifdef O_DIRECT
        directFd_ = ::open(tempPath_.c_str(), O_WRONLY | O_DIRECT | O_CLOEXEC);  // refused by some file systems
#endif
        directOpened_ = directFd_.load();
    }
    if (directFd_ < 0) return writeAt(offset, bytes);
    if (runs_.size() <= run) runs_.resize(run + 1);
    if (!runs_[run]) runs_[run] = std::make_unique<Run>();
    Run& r = *runs_[run];
    if (!r.open || offset != r.at + r.used) {  // a new run: the bytes up to an aligned offset through the cache
        flushRun(run);
        const size_t head = static_cast<size_t>(
            std::min<uint64_t>(bytes.size(), (kDirectAlign - offset % kDirectAlign) % kDirectAlign));
        writeAt(offset, bytes.first(head));
        bytes = bytes.subspan(head);
        offset += head;
        if (offset % kDirectAlign != 0) return;  // all of it went through the cache
        if (!r.fill && !(r.fill = static_cast<std::byte*>(std::aligned_alloc(kDirectAlign, kRunBuffer))))
            throw Error(path_ + ": out of memory for a write buffer");
        r.at = offset, r.used = 0, r.open = true;
    }
    while (!bytes.empty()) {
        const size_t take = std::min(bytes.size(), kRunBuffer - r.used);
        std::memcpy(r.fill + r.used, bytes.data(), take);
        r.used += take;
        bytes = bytes.subspan(take);
        if (r.used == kRunBuffer) writeDirect(r);
    }
}

void AtomicFileWriter::writeDirect(Run& r) {
    if (r.writing.valid()) r.writing.get();  // the spare's write: done (or its error thrown) before it fills again
    if (!r.spare && !(r.spare = static_cast<std::byte*>(std::aligned_alloc(kDirectAlign, kRunBuffer))))
        throw Error(path_ + ": out of memory for a write buffer");
    std::swap(r.fill, r.spare);
    r.writing = std::async(std::launch::async, [this, buffer = r.spare, bytes = r.used, at = r.at] {
        for (size_t done = 0; done < bytes;) {
            const int direct = directFd_.load(), fd = direct >= 0 ? direct : fd_;
            const ssize_t n = ::pwrite(fd, buffer + done, bytes - done, static_cast<off_t>(at + done));
            if (n < 0 && errno == EINTR) continue;
            if (n < 0 && errno == EINVAL && done == 0 && fd == direct) {  // refused after all: through the cache
                directFd_.store(-1);
                continue;
            }
            if (n <= 0) fail("write failed");
            done += static_cast<size_t>(n);
        }
    });
    r.at += r.used;
    r.used = 0;
}

void AtomicFileWriter::flushRun(size_t run) {
    if (run >= runs_.size() || !runs_[run] || !runs_[run]->open) return;
    Run& r = *runs_[run];
    if (r.writing.valid()) r.writing.get();
    writeAt(r.at, std::span(r.fill, r.used));  // the tail: any length, through the cache
    r.at += r.used;
    r.used = 0;
    r.open = false;
    std::free(r.fill);
    std::free(r.spare);
    r.fill = r.spare = nullptr;
}

void AtomicFileWriter::write(std::span<const std::byte> bytes) {
    writeAt(position_, bytes);
    position_ += bytes.size();
}

void AtomicFileWriter::writeZeros(size_t count) {
    static const std::byte zeros[4096] = {};
    while (count > 0) {
        size_t n = count < sizeof zeros ? count : sizeof zeros;
        write(std::span<const std::byte>(zeros, n));
        count -= n;
    }
}

void AtomicFileWriter::commit() {
    for (size_t run = 0; run < runs_.size(); ++run) flushRun(run);
    if (::fsync(fd_) != 0) fail("fsync failed");
    int rc = ::close(fd_);
    fd_ = -1;
    if (rc != 0) fail("close failed");
    if (std::rename(tempPath_.c_str(), path_.c_str()) != 0) fail("cannot rename the temporary file into place");
    committed_ = true;
}

AtomicPath::AtomicPath(std::string path) : path_(std::move(path)) {
    // The library opens temp_ by name and truncates it: the same file, so lockFd_'s lock stays on it.
    lockFd_ = createLockedTemporary(path_, temp_);
}

AtomicPath::~AtomicPath() {
    if (!committed_) std::remove(temp_.c_str());
    if (lockFd_ >= 0) ::close(lockFd_);
}

void AtomicPath::commit() {
    // Flush the library's bytes to disk before the rename makes them the real file.
    int fd = ::open(temp_.c_str(), O_RDONLY);
    if (fd < 0) throw Error(path_ + ": the temporary output " + temp_ + " was not written");
    ::fsync(fd);
    ::close(fd);
    ::chmod(temp_.c_str(), 0644);
    if (std::rename(temp_.c_str(), path_.c_str()) != 0)
        throw Error(path_ + ": cannot rename the temporary file into place: " + std::strerror(errno));
    committed_ = true;
}

}  // namespace hc
