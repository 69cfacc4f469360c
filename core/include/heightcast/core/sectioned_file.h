// heightcast/core/sectioned_file.h: the container both heightcast formats share (.hcg grids,
// .hci influence caches): a checksummed header, a section table, aligned sections.
//
//   offset  size  field
//   0       8     magic (the format's)
//   8       2     major version: a reader refuses a newer major
//   10      2     minor version: a newer minor only adds sections (or keys) a reader may skip
//   12      4     header bytes (128)
//   16      8     file bytes: must equal the file's length (truncation check)
//   24      36    the format's own fields
//   60      4     section count
//   64      56    the format's own fields
//   120     4     CRC-32 of the section table
//   124     4     CRC-32 of bytes 0..123
//   128     32*S  section table: { u32 kind, u32 index, u64 offset, u64 bytes, u32 crc32, u32 zero }
//   ...           sections at 64-byte aligned offsets, in table order; zero padding between them;
//                 nothing after the last one.
// Every byte is covered: by a CRC, by the zero checks, or by the size check. Little-endian throughout.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

namespace hc {

constexpr uint32_t kFileHeaderBytes = 128;
constexpr uint32_t kFileSectionEntryBytes = 32;
constexpr uint32_t kFileSectionAlign = 64;

struct FileFormat {
    std::array<char, 8> magic;
    uint16_t major, minor;
    const char* what;  // "heightcast grid (.hcg)": used in messages
    std::vector<uint32_t> knownKinds;
};

struct FileSection {
    uint32_t kind = 0, index = 0;
    uint64_t offset = 0, bytes = 0;
    uint32_t crc = 0;
};

// A read-only memory mapping of a whole file (fuzz builds: an exact-size heap copy, see HC_FUZZ_HEAP_FILES).
class MappedFile {
public:
    explicit MappedFile(const std::string& path);  // throws hc::Error
    ~MappedFile();
    MappedFile(const MappedFile&) = delete;
    MappedFile& operator=(const MappedFile&) = delete;
    std::span<const std::byte> bytes() const { return {data_, size_}; }

private:
    const std::byte* data_ = nullptr;
    size_t size_ = 0;
};

// Maps a file and validates the container: size, magic, version, both CRCs, declared size, section
// placement, zero padding and every section's CRC. Errors name the file and the byte offset.
class SectionedFileReader {
public:
    SectionedFileReader(const std::string& path, const FileFormat& format);
    const std::byte* header() const { return map_->bytes().data(); }
    uint16_t minor() const { return minor_; }
    const std::vector<FileSection>& sections() const { return sections_; }
    std::span<const std::byte> data(const FileSection& s) const { return map_->bytes().subspan(s.offset, s.bytes); }
    // The offset of section s's table entry (for messages about its fields).
    static uint64_t entryOffset(size_t s) { return kFileHeaderBytes + s * kFileSectionEntryBytes; }
    std::shared_ptr<const MappedFile> mapping() const { return map_; }
    const std::string& path() const { return path_; }
    [[noreturn]] void fail(uint64_t offset, const std::string& what) const;
    [[noreturn]] void failFile(const std::string& what) const;

private:
    std::string path_;
    std::shared_ptr<const MappedFile> map_;
    uint16_t minor_ = 0;
    std::vector<FileSection> sections_;
};

// Writes a container atomically. Sections are placed up front (their sizes known), written in
// pieces as data arrives (each section front to back, sections may interleave), and the header,
// table and CRCs go in at commit(). Nothing appears under `path` unless commit() succeeds.
class SectionedFileWriter {
public:
    // `layout`: kind, index and bytes of the sections known now; `laterSections`: how many more
    // addSection() will add before commit (the table's size must be known first).
    SectionedFileWriter(const std::string& path, const FileFormat& format, std::vector<FileSection> layout,
                        size_t laterSections = 0);
    ~SectionedFileWriter();
    SectionedFileWriter(const SectionedFileWriter&) = delete;
    SectionedFileWriter& operator=(const SectionedFileWriter&) = delete;

    const FileSection& section(size_t s) const;
    void append(size_t s, std::span<const std::byte> bytes);
    void addSection(uint32_t kind, uint32_t index, std::span<const std::byte> bytes);
    // `header`: kFileHeaderBytes with the format's own fields set; the rest is filled in here.
    void commit(std::vector<std::byte> header);
    const std::string& path() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace hc
