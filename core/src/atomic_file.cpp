#include "heightcast/core/atomic_file.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
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

AtomicFileWriter::~AtomicFileWriter() {
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
