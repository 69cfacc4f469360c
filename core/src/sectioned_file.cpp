#include "heightcast/core/sectioned_file.h"

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <new>

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include "heightcast/core/atomic_file.h"
#include "heightcast/core/checksum.h"
#include "heightcast/core/bytes.h"
#include "heightcast/core/error.h"

namespace hc {
namespace {

namespace off {
constexpr size_t major = 8, minor = 10, headerBytes = 12, fileBytes = 16, sectionCount = 60, tableCrc = 120, headerCrc = 124;
}

uint64_t alignUp(uint64_t v) { return (v + kFileSectionAlign - 1) / kFileSectionAlign * kFileSectionAlign; }

}  // namespace

MappedFile::MappedFile(const std::string& path) {
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) throw Error(path + ": no such file");
    if (std::filesystem::is_directory(path, ec)) throw Error(path + ": is a directory, not a file");
    int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) throw Error(path + ": cannot open for reading: " + std::strerror(errno));
    struct stat st {};
    if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
        ::close(fd);
        throw Error(path + ": not a regular file");
    }
    size_ = static_cast<size_t>(st.st_size);
#ifdef HC_FUZZ_HEAP_FILES
    // Fuzz builds (HC_FUZZ, fuzz/): the file goes into a heap block of exactly its size, so AddressSanitizer
    // reports a read past its end; a mapping would quietly return the zeros at the end of its last page.
    if (size_ > 0) {
        auto* p = static_cast<std::byte*>(::operator new(size_, std::align_val_t{kFileSectionAlign}));
        for (size_t done = 0; done < size_;) {
            const ssize_t n = ::pread(fd, p + done, size_ - done, static_cast<off_t>(done));
            if (n <= 0) {
                ::operator delete(p, std::align_val_t{kFileSectionAlign});
                ::close(fd);
                throw Error(path + ": cannot read");
            }
            done += static_cast<size_t>(n);
        }
        data_ = p;
    }
#else
    if (size_ > 0) {
        void* p = ::mmap(nullptr, size_, PROT_READ, MAP_PRIVATE, fd, 0);
        if (p == MAP_FAILED) {
            int err = errno;
            ::close(fd);
            throw Error(path + ": cannot map into memory: " + std::strerror(err));
        }
        data_ = static_cast<const std::byte*>(p);
    }
#endif
    ::close(fd);
}

MappedFile::~MappedFile() {
#ifdef HC_FUZZ_HEAP_FILES
    if (data_) ::operator delete(const_cast<std::byte*>(data_), std::align_val_t{kFileSectionAlign});
#else
    if (data_) ::munmap(const_cast<std::byte*>(data_), size_);
#endif
}

void SectionedFileReader::fail(uint64_t offset, const std::string& what) const {
    throw Error(path_ + ": at byte offset " + std::to_string(offset) + ": " + what);
}
void SectionedFileReader::failFile(const std::string& what) const { throw Error(path_ + ": " + what); }

SectionedFileReader::SectionedFileReader(const std::string& path, const FileFormat& format)
    : path_(path), map_(std::make_shared<MappedFile>(path)) {
    const auto bytes = map_->bytes();
    const uint64_t size = bytes.size();
    const std::byte* h = bytes.data();
    if (size < kFileHeaderBytes)
        failFile("truncated: " + std::to_string(size) + " bytes, the header alone is " + std::to_string(kFileHeaderBytes) +
                 " (not a " + format.what + " file?)");
    if (std::memcmp(h, format.magic.data(), 8) != 0) fail(0, std::string("bad magic: not a ") + format.what + " file");
    const auto major = bytes::load<uint16_t>(h + off::major);
    minor_ = bytes::load<uint16_t>(h + off::minor);
    const std::string version = std::to_string(major) + "." + std::to_string(minor_);
    if (major > format.major)
        fail(off::major, "format version " + version + " is newer than this reader (" + std::to_string(format.major) + "." +
                             std::to_string(format.minor) + "); upgrade heightcast to read it");
    if (major != format.major) fail(off::major, "unknown format version " + version);
    if (bytes::load<uint32_t>(h + off::headerCrc) != crc32(std::span(h, off::headerCrc))) fail(off::headerCrc, "header checksum mismatch (corrupt header)");
    if (bytes::load<uint32_t>(h + off::headerBytes) != kFileHeaderBytes)
        fail(off::headerBytes, "header size " + std::to_string(bytes::load<uint32_t>(h + off::headerBytes)) + " is not " + std::to_string(kFileHeaderBytes));
    const uint64_t declared = bytes::load<uint64_t>(h + off::fileBytes);
    if (declared != size)
        fail(off::fileBytes, "header declares " + std::to_string(declared) + " bytes but the file has " + std::to_string(size) +
                                 (size < declared ? " (truncated)" : " (trailing data)"));
    const uint32_t count = bytes::load<uint32_t>(h + off::sectionCount);
    const uint64_t tableEnd = kFileHeaderBytes + uint64_t{count} * kFileSectionEntryBytes;
    if (count > 4096 || tableEnd > size)
        fail(off::sectionCount, "section table of " + std::to_string(count) + " entries runs past the end of the file");
    if (bytes::load<uint32_t>(h + off::tableCrc) != crc32(std::span(h + kFileHeaderBytes, tableEnd - kFileHeaderBytes)))
        fail(kFileHeaderBytes, "section table checksum mismatch (corrupt section table)");
    uint64_t cursor = tableEnd;
    for (uint32_t s = 0; s < count; ++s) {
        const uint64_t at = entryOffset(s);
        FileSection e;
        e.kind = bytes::load<uint32_t>(h + at);
        e.index = bytes::load<uint32_t>(h + at + 4);
        e.offset = bytes::load<uint64_t>(h + at + 8);
        e.bytes = bytes::load<uint64_t>(h + at + 16);
        e.crc = bytes::load<uint32_t>(h + at + 24);
        if (bytes::load<uint32_t>(h + at + 28) != 0) fail(at + 28, "reserved section-table field is not zero");
        if (e.offset % kFileSectionAlign != 0 || e.offset < cursor || e.offset > size || e.bytes > size - e.offset)
            fail(at + 8, "section " + std::to_string(s) + " (offset " + std::to_string(e.offset) + ", " + std::to_string(e.bytes) +
                             " bytes) is misplaced or runs past the end of the file");
        for (uint64_t p = cursor; p < e.offset; ++p)
            if (h[p] != std::byte{0}) fail(p, "padding byte is not zero");
        if (crc32(std::span(h + e.offset, e.bytes)) != e.crc)
            fail(e.offset, "checksum mismatch in section " + std::to_string(s) + " (corrupt data)");
        bool known = false;
        for (uint32_t k : format.knownKinds) known |= k == e.kind;
        if (!known && minor_ <= format.minor) fail(at, "unknown section kind " + std::to_string(e.kind));
        cursor = e.offset + e.bytes;
        sections_.push_back(e);
    }
    if (cursor != size) fail(cursor, "data after the last section");
}

struct SectionedFileWriter::Impl {
    Impl(const std::string& p, const FileFormat& f) : out(p), format(f) {}
    AtomicFileWriter out;
    FileFormat format;
    std::vector<FileSection> sections;
    std::vector<uint64_t> written;  // bytes appended so far, per section
    size_t tableEntries = 0;
    uint64_t end = 0;  // end of the last placed section
};

SectionedFileWriter::SectionedFileWriter(const std::string& path, const FileFormat& format, std::vector<FileSection> layout,
                                         size_t laterSections)
    : impl_(std::make_unique<Impl>(path, format)) {
    impl_->tableEntries = layout.size() + laterSections;
    uint64_t cursor = kFileHeaderBytes + impl_->tableEntries * kFileSectionEntryBytes;
    for (FileSection& s : layout) {
        s.offset = alignUp(cursor);
        s.crc = 0;
        cursor = s.offset + s.bytes;
    }
    impl_->end = cursor;
    impl_->sections = std::move(layout);
    impl_->written.assign(impl_->sections.size(), 0);
}

SectionedFileWriter::~SectionedFileWriter() = default;
const std::string& SectionedFileWriter::path() const { return impl_->out.path(); }
const FileSection& SectionedFileWriter::section(size_t s) const { return impl_->sections.at(s); }

void SectionedFileWriter::append(size_t s, std::span<const std::byte> bytes) {
    Impl& w = *impl_;
    FileSection& sec = w.sections.at(s);
    if (bytes.size() > sec.bytes - w.written[s]) throw Error(path() + ": section " + std::to_string(s) + " overflows its declared size");
    w.out.writeAt(sec.offset + w.written[s], bytes);
    sec.crc = crc32(bytes, sec.crc);
    w.written[s] += bytes.size();
}

void SectionedFileWriter::addSection(uint32_t kind, uint32_t index, std::span<const std::byte> bytes) {
    Impl& w = *impl_;
    if (w.sections.size() >= w.tableEntries) throw Error(path() + ": more sections than the table holds");
    FileSection s{kind, index, alignUp(w.end), bytes.size(), 0};
    w.sections.push_back(s);
    w.written.push_back(0);
    w.end = s.offset + s.bytes;
    append(w.sections.size() - 1, bytes);
}

void SectionedFileWriter::commit(std::vector<std::byte> header) {
    Impl& w = *impl_;
    if (w.sections.size() != w.tableEntries) throw Error(path() + ": " + std::to_string(w.sections.size()) + " sections of " + std::to_string(w.tableEntries));
    for (size_t s = 0; s < w.sections.size(); ++s)
        if (w.written[s] != w.sections[s].bytes)
            throw Error(path() + ": section " + std::to_string(s) + " has " + std::to_string(w.written[s]) + " of its " +
                        std::to_string(w.sections[s].bytes) + " bytes");
    // Zero padding between sections: the gaps were never written (a sparse hole), make them explicit.
    uint64_t cursor = kFileHeaderBytes + w.sections.size() * kFileSectionEntryBytes;
    const std::vector<std::byte> zeros(kFileSectionAlign, std::byte{0});
    for (const FileSection& s : w.sections) {
        if (s.offset > cursor) w.out.writeAt(cursor, std::span(zeros).first(s.offset - cursor));
        cursor = s.offset + s.bytes;
    }
    header.resize(kFileHeaderBytes + w.sections.size() * kFileSectionEntryBytes, std::byte{0});
    std::memcpy(header.data(), w.format.magic.data(), 8);
    bytes::store(header, off::major, w.format.major);
    bytes::store(header, off::minor, w.format.minor);
    bytes::store(header, off::headerBytes, kFileHeaderBytes);
    bytes::store(header, off::fileBytes, cursor);
    bytes::store(header, off::sectionCount, static_cast<uint32_t>(w.sections.size()));
    for (size_t s = 0; s < w.sections.size(); ++s) {
        const size_t at = kFileHeaderBytes + s * kFileSectionEntryBytes;
        bytes::store(header, at, w.sections[s].kind);
        bytes::store(header, at + 4, w.sections[s].index);
        bytes::store(header, at + 8, w.sections[s].offset);
        bytes::store(header, at + 16, w.sections[s].bytes);
        bytes::store(header, at + 24, w.sections[s].crc);
        bytes::store(header, at + 28, uint32_t{0});
    }
    bytes::store(header, off::tableCrc, crc32(std::span(header).subspan(kFileHeaderBytes)));
    bytes::store(header, off::headerCrc, crc32(std::span(header).first(off::headerCrc)));
    w.out.writeAt(0, header);
    w.out.commit();
}

}  // namespace hc
