#include "heightcast/grid/atomic_file.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <vector>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include "heightcast/grid/error.h"

namespace hc {

AtomicFileWriter::AtomicFileWriter(std::string path) : path_(std::move(path)) {
    // mkstemp in the target's directory: rename() is atomic only within one file system.
    std::string pattern = path_ + ".tmp.XXXXXX";
    std::vector<char> buf(pattern.begin(), pattern.end());
    buf.push_back('\0');
    fd_ = mkstemp(buf.data());
    if (fd_ < 0) throw Error(path_ + ": cannot create a file there: " + std::strerror(errno));
    tempPath_ = buf.data();
    fchmod(fd_, 0644);
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
    std::filesystem::path p(path_);
    const std::string ext = p.extension().string();
    std::string pattern = (p.parent_path() / (p.stem().string() + ".tmp.XXXXXX" + ext)).string();
    if (p.parent_path().empty()) pattern = p.stem().string() + ".tmp.XXXXXX" + ext;
    std::vector<char> buf(pattern.begin(), pattern.end());
    buf.push_back('\0');
    int fd = mkstemps(buf.data(), static_cast<int>(ext.size()));
    if (fd < 0) throw Error(path_ + ": cannot create a file there: " + std::strerror(errno));
    ::close(fd);
    temp_ = buf.data();
    std::remove(temp_.c_str());  // libraries create it themselves; the unique name is reserved by us
}

AtomicPath::~AtomicPath() {
    if (!committed_) std::remove(temp_.c_str());
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
