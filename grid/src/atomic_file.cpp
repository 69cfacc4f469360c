#include "heightcast/grid/atomic_file.h"

#include <cerrno>
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
    int fd = mkstemp(buf.data());
    if (fd < 0) throw Error(path_ + ": cannot create a file there: " + std::strerror(errno));
    tempPath_ = buf.data();
    fchmod(fd, 0644);
    file_ = fdopen(fd, "wb");
    if (!file_) {
        ::close(fd);
        std::remove(tempPath_.c_str());
        throw Error(path_ + ": cannot open for writing: " + std::strerror(errno));
    }
}

AtomicFileWriter::~AtomicFileWriter() {
    if (file_) std::fclose(file_);
    if (!committed_ && !tempPath_.empty()) std::remove(tempPath_.c_str());
}

void AtomicFileWriter::fail(const std::string& what) {
    int err = errno;
    throw Error(path_ + ": " + what + ": " + std::strerror(err));
}

void AtomicFileWriter::write(std::span<const std::byte> bytes) {
    if (bytes.empty()) return;
    if (std::fwrite(bytes.data(), 1, bytes.size(), file_) != bytes.size()) fail("write failed");
    position_ += bytes.size();
}

void AtomicFileWriter::writeZeros(size_t count) {
    static const std::byte zeros[256] = {};
    while (count > 0) {
        size_t n = count < sizeof zeros ? count : sizeof zeros;
        write(std::span<const std::byte>(zeros, n));
        count -= n;
    }
}

void AtomicFileWriter::commit() {
    if (std::fflush(file_) != 0) fail("write failed");
    if (fsync(fileno(file_)) != 0) fail("fsync failed");
    int rc = std::fclose(file_);
    file_ = nullptr;
    if (rc != 0) fail("close failed");
    if (std::rename(tempPath_.c_str(), path_.c_str()) != 0) fail("cannot rename the temporary file into place");
    committed_ = true;
}

}  // namespace hc
