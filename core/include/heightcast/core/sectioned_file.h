// heightcast/core/sectioned_file.h: the container the heightcast formats share (.hcg grids, .hci influence caches,
// .hcp surface pyramids; byte tables in docs/formats/): a checksummed header, a section table, aligned sections.
//
//   offset  size  field
//   0       8     magic (the format's)
//   8       2     major version: a reader refuses a newer major
//   10      2     minor version: a newer minor is read (each format says what an older reader misses)
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
//
// Block checksums (the formats' minors from FileFormat::blockChecksumsSince on: .hcg 1.2, .hci 1.1, .hcp 1.0): the
// last section, of the container's own kind kFileBlockChecksumsKind, holds a CRC-32 per block of every
// section before it, so a reader checks exactly the blocks covering the bytes it reads:
//   0       4     block bytes B (a power of two, 4 KiB .. 1 GiB; the writer uses kFileBlockBytes)
//   4       4     zero
//   8       4*k   per section in table order: CRC-32 of each of its ceil(bytes / B) blocks (the last one short)
// Each section's table CRC stays (readers of older minors skip the unknown kind and check those); a reader
// of this minor checks at open that each table CRC equals the block CRCs combined (no data pass). Files of
// older minors have one CRC per section: a section is then checked whole when first touched.
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
// The container's own section kind (formats use small kinds; the high bit is the container's).
constexpr uint32_t kFileBlockChecksumsKind = 0x80000001u;
// 1 MiB blocks: the table costs 4 bytes per MiB (5 KB for a 105 M-cell grid, read and checked at open);
// a point lookup's binary search over a 1 GB section touches ~10 distinct blocks, 10 MiB of CRC
// (crc32, its throughput in docs/benchmarks.md), well inside a 1 s probe;
// smaller blocks would cut that but grow the table and the per-block bookkeeping, larger ones would make a
// first touch cost more than the read it guards.
constexpr uint32_t kFileBlockBytes = 1u << 20;

struct FileFormat {
    std::array<char, 8> magic;
    uint16_t major, minor;
    const char* what;  // "heightcast grid (.hcg)": used in messages
    std::vector<uint32_t> knownKinds;
    // The first minor whose files carry block checksums: the writer adds them when `minor` is at least
    // this, and a reader requires them in files of such minors. Default: never (one CRC per section).
    uint16_t blockChecksumsSince = 0xFFFF;
};

struct FileSection {
    uint32_t kind = 0, index = 0;
    uint64_t offset = 0, bytes = 0;
    uint32_t crc = 0;
};

// From now on, files are read into exact-size heap blocks instead of mapped (MappedFile): the fuzz targets call it
// first, so that AddressSanitizer reports a read past a file's end, where a mapping would quietly return the zeros at
// the end of its last page. Tools and tests map (releasePages() then drops pages from resident memory).
void readFilesIntoHeap(bool on);

// A read-only memory mapping of a whole file (or an exact-size heap copy: readFilesIntoHeap).
class MappedFile {
public:
    explicit MappedFile(const std::string& path);  // throws hc::Error
    ~MappedFile();
    MappedFile(const MappedFile&) = delete;
    MappedFile& operator=(const MappedFile&) = delete;
    std::span<const std::byte> bytes() const { return {data_, size_}; }
    // Drops the mapping's pages from this process's resident memory (madvise MADV_DONTNEED): they stay in the page
    // cache and are read back from it when touched again, the same bytes (the mapping is read-only).
    void releasePages() const;
    // The same for the whole pages inside bytes [offset, offset + bytes) of the file.
    void releasePages(uint64_t offset, uint64_t bytes) const;

private:
    const std::byte* data_ = nullptr;
    size_t size_ = 0;
    bool heap_ = false;  // data_ is a heap block (readFilesIntoHeap), not a mapping
};

// Maps a file and validates the container at open without a pass over the data: size, magic, version,
// header and table CRCs, declared size, section placement, zero padding, and the block checksum table
// (its CRC, its size, and that it agrees with every section's table CRC). Section data is checked when
// first read: read()/data() check the blocks covering the requested bytes, each block once (an atomic
// bit per block: concurrent readers are safe, a block may at worst be checked twice). Errors name the
// file and the byte offset (of the header field, table entry or corrupt block).
class SectionedFileReader {
public:
    SectionedFileReader(const std::string& path, const FileFormat& format);
    ~SectionedFileReader();
    SectionedFileReader(const SectionedFileReader&) = delete;
    SectionedFileReader& operator=(const SectionedFileReader&) = delete;
    const std::byte* header() const { return map_->bytes().data(); }
    uint16_t minor() const { return minor_; }
    // The format's sections, in table order (the block checksum table is the container's: not listed).
    const std::vector<FileSection>& sections() const { return sections_; }
    // Bytes [offset, offset + bytes) of section `s` (an element of sections()), after checking the blocks
    // that cover them; throws hc::Error naming the block's offset on a mismatch, or if the range runs past s.
    std::span<const std::byte> read(const FileSection& s, uint64_t offset, uint64_t bytes) const;
    // All of section `s`, checked.
    std::span<const std::byte> data(const FileSection& s) const { return read(s, 0, s.bytes); }
    // Checks every block of every section (what the constructor does not).
    void verifyAll() const;
    // The block size of the file's checksums; 0 for a file of an older minor (one CRC per section).
    uint64_t blockBytes() const { return blockBytes_; }
    // Section bytes whose checksums have been checked so far (each block counted once).
    uint64_t bytesChecked() const;
    // The offset of section s's table entry (for messages about its fields).
    static uint64_t entryOffset(size_t s) { return kFileHeaderBytes + s * kFileSectionEntryBytes; }
    std::shared_ptr<const MappedFile> mapping() const { return map_; }
    void releasePages() const { map_->releasePages(); }  // MappedFile::releasePages
    // Checks every block of section `s` a chunk at a time and releases each chunk's pages after it: the whole section
    // checked while at most a chunk of it is resident (a later read pages in only what it touches).
    void checkReleasing(const FileSection& s) const;
    const std::string& path() const { return path_; }
    [[noreturn]] void fail(uint64_t offset, const std::string& what) const;
    [[noreturn]] void failFile(const std::string& what) const;

private:
    struct Checks;  // per section: where its block CRCs are; the bits of the blocks checked
    void checkBlock(size_t section, uint64_t block) const;

    std::string path_;
    std::shared_ptr<const MappedFile> map_;
    uint16_t minor_ = 0;
    uint64_t blockBytes_ = 0;
    std::vector<FileSection> sections_;
    std::unique_ptr<Checks> checks_;
};

// A piece of a placed section that another process wrote (SectionedFilePart): bytes [offset, offset + bytes) of section
// `section` (an index into the writer's layout), all inside one checksum block, and their CRC-32.
struct FilePiece {
    uint32_t section = 0, zero = 0;
    uint64_t offset = 0, bytes = 0;
    uint64_t crc = 0;
};

// Where a SectionedFileWriter's placed sections lie in its temporary, for the processes that write parts of them.
struct FilePlacement {
    std::string path;           // the target (for messages)
    std::string temporaryPath;  // what the parts are written into
    std::vector<FileSection> sections;
    std::vector<std::byte> encode() const;
    static FilePlacement decode(std::span<const std::byte> bytes);  // throws hc::Error on a malformed table
};

// Writes a container atomically. Sections are placed up front (their sizes known), written in
// pieces as data arrives (each section front to back, sections may interleave), and the header,
// table and CRCs go in at commit(). Block CRCs are computed as data is appended (each section's CRC is
// then combined from them); the block checksum table, where the format's minor has one, is added at
// commit() as the last section. Nothing appears under `path` unless commit() succeeds.
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

    // Under mpirun (docs/design.md section 7) other processes write parts of the placed sections straight into this
    // writer's temporary (SectionedFilePart over placement()); addPieces() then takes their pieces' CRCs as if their
    // bytes had been append()ed: each piece must start where its section holds bytes up to so far.
    FilePlacement placement() const;
    void addPieces(std::span<const FilePiece> pieces);

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// A part of a container that another process's SectionedFileWriter writes (under mpirun, each rank its own run of a
// section's bytes): bytes written straight into that writer's temporary, which must lie on a file system both
// processes see, and the CRC-32 of every piece of a checksum block they cover, for that writer's addPieces(). Writes
// nothing else; the writer's commit() (or its removal of the temporary) ends the file.
class SectionedFilePart {
public:
    explicit SectionedFilePart(FilePlacement placement);  // throws hc::Error if the temporary cannot be opened
    ~SectionedFilePart();
    SectionedFilePart(const SectionedFilePart&) = delete;
    SectionedFilePart& operator=(const SectionedFilePart&) = delete;
    // Bytes [at, at + bytes.size()) of placed section s.
    void writeAt(size_t s, uint64_t at, std::span<const std::byte> bytes);
    // Reads back bytes [at, at + out.size()) of placed section s (as this part wrote them; before finish()).
    void readAt(size_t s, uint64_t at, std::span<std::byte> out) const;
    // Flushes (fsync) and closes the temporary; the pieces written, in the order written (runs that continue one
    // another within a block are one piece).
    std::vector<FilePiece> finish();

private:
    FilePlacement placement_;
    int fd_ = -1;
    std::vector<FilePiece> pieces_;
};

}  // namespace hc
