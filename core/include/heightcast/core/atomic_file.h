// heightcast/core/atomic_file.h: write a file so that it appears whole or not at all.
//
// Bytes go to a temporary file beside the target; commit() flushes, fsyncs and renames it over
// the target. If the writer is destroyed without commit() (an exception, a failed check), the
// temporary file is removed: no half-written file ever exists under the real name. A temporary is named
// TARGET.tmp.XXXXXX; one left by a killed run (kill -9) is removed by the next write of the same target.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

namespace hc {

class AtomicFileWriter {
public:
    explicit AtomicFileWriter(std::string path);  // throws hc::Error if the temporary cannot be created
    ~AtomicFileWriter();
    AtomicFileWriter(const AtomicFileWriter&) = delete;
    AtomicFileWriter& operator=(const AtomicFileWriter&) = delete;

    void write(std::span<const std::byte> bytes);                     // at position(), which then advances
    void writeAt(uint64_t offset, std::span<const std::byte> bytes);  // anywhere; position() unchanged
    void writeZeros(size_t count);
    uint64_t position() const { return position_; }
    void commit();  // throws hc::Error on any I/O failure; the target is then untouched

    // Front-to-back writes of one long run of bytes (a file section), run `run` at `offset` on: staged in 4 MiB
    // aligned buffers written with O_DIRECT where the file system takes it, past the page cache (copying gigabytes
    // into the cache costs more CPU than the disk takes to write them); the unaligned head and the tail go through
    // the cache. A write that does not continue its run starts it again. flushRun() writes a run's tail; commit()
    // flushes every run.
    void writeRun(size_t run, uint64_t offset, std::span<const std::byte> bytes);
    void flushRun(size_t run);

    const std::string& path() const { return path_; }
    // The temporary being written (TARGET.tmp.XXXXXX): under mpirun other ranks write their parts into it
    // (SectionedFilePart) before this writer's commit().
    const std::string& temporaryPath() const { return tempPath_; }

private:
    void fail(const std::string& what);
    std::string path_;
    std::string tempPath_;
    int fd_ = -1;
    uint64_t position_ = 0;
    size_t unflushed_ = 0;  // bytes written since the last write-back was started
    void startWriteBack(size_t written);
    bool committed_ = false;
    bool directTried_ = false;
    std::atomic<int> directFd_{-1};  // the temporary opened with O_DIRECT, or -1 (refused, or refused since)
    int directOpened_ = -1;          // the descriptor to close
    struct Run;
    std::vector<std::unique_ptr<Run>> runs_;
    void writeDirect(Run& r);
};

// For libraries that insist on writing a file by name (GDAL, OpenEXR, OpenVDB): a unique temporary
// path beside the target (TARGET.tmp.XXXXXX, created empty: the library must truncate it, not replace it), renamed
// over the target by commit() and removed by the destructor otherwise.
class AtomicPath {
public:
    explicit AtomicPath(std::string path);  // throws hc::Error if the directory is not writable
    ~AtomicPath();
    AtomicPath(const AtomicPath&) = delete;
    AtomicPath& operator=(const AtomicPath&) = delete;
    const std::string& temp() const { return temp_; }
    const std::string& path() const { return path_; }
    void commit();  // throws hc::Error; the temporary must have been written and closed

private:
    std::string path_, temp_;
    int lockFd_ = -1;  // holds the temporary's flock (see atomic_file.cpp)
    bool committed_ = false;
};

}  // namespace hc
