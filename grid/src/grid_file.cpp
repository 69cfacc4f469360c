#include "heightcast/grid/grid_file.h"

#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <sstream>
#include <vector>

#include "heightcast/grid/atomic_file.h"
#include "heightcast/grid/checksum.h"
#include "heightcast/grid/error.h"

namespace hc {
namespace {

constexpr char kMagic[8] = {'\x89', 'H', 'C', 'G', 'R', 'I', 'D', '\n'};
enum SectionKind : uint32_t { kMeta = 1, kCells = 2, kLayer = 3 };

// Header field offsets (see grid_file.h); pinned here and by the golden-bytes test.
namespace off {
constexpr size_t magic = 0, major = 8, minor = 10, headerBytes = 12, fileBytes = 16, cellCount = 24,
                 originX = 32, originY = 40, finestCell = 48, rootLevel = 56, minLevel = 57, maxLevel = 58,
                 layerCount = 59, sectionCount = 60, contentHash = 64, structureHash = 72, reserved = 80,
                 tableCrc = 120, headerCrc = 124;
}
static_assert(off::headerCrc + 4 == kGridHeaderBytes);

struct SectionEntry {
    uint32_t kind = 0, index = 0;
    uint64_t offset = 0, bytes = 0;
    uint32_t crc = 0;
};

template <typename T>
void put(std::vector<std::byte>& buf, size_t at, T v) {
    std::memcpy(buf.data() + at, &v, sizeof v);
}
template <typename T>
T get(const std::byte* p) {
    T v;
    std::memcpy(&v, p, sizeof v);
    return v;
}

uint64_t alignUp(uint64_t v) { return (v + kGridSectionAlign - 1) / kGridSectionAlign * kGridSectionAlign; }

std::string fmtDouble(double v) {
    char buf[32];
    auto r = std::to_chars(buf, buf + sizeof buf, v);  // shortest exact round trip
    return std::string(buf, r.ptr);
}

void appendString(std::vector<std::byte>& out, const std::string& s) {
    auto n = static_cast<uint32_t>(s.size());
    auto* p = reinterpret_cast<const std::byte*>(&n);
    out.insert(out.end(), p, p + 4);
    auto* q = reinterpret_cast<const std::byte*>(s.data());
    out.insert(out.end(), q, q + s.size());
}

std::vector<std::byte> encodeMeta(const Grid& g) {
    std::vector<std::pair<std::string, std::string>> kv;
    kv.emplace_back("crs_wkt", g.crsWkt);
    for (size_t l = 0; l < g.layers.size(); ++l) {
        kv.emplace_back("layer." + std::to_string(l) + ".name", g.layers[l].name);
        kv.emplace_back("layer." + std::to_string(l) + ".units", g.layers[l].units);
    }
    const IngestStats& s = g.stats;
    kv.emplace_back("ingest.source", s.sourcePath);
    kv.emplace_back("ingest.source_crs", s.sourceCrsName);
    kv.emplace_back("ingest.source_width", std::to_string(s.sourceWidth));
    kv.emplace_back("ingest.source_height", std::to_string(s.sourceHeight));
    kv.emplace_back("ingest.valid_pixels", std::to_string(s.validPixels));
    kv.emplace_back("ingest.tolerance_m", fmtDouble(s.toleranceM));
    kv.emplace_back("ingest.max_dev_m", fmtDouble(s.maxDevM));
    kv.emplace_back("ingest.rms_dev_m", fmtDouble(s.rmsDevM));
    kv.emplace_back("ingest.seconds", fmtDouble(s.seconds));
    std::vector<std::byte> out;
    for (auto& [k, v] : kv) {
        appendString(out, k);
        appendString(out, v);
    }
    return out;
}

class Reader {
public:
    Reader(std::string path, std::vector<std::byte> data) : path_(std::move(path)), d_(std::move(data)) {}

    [[noreturn]] void fail(uint64_t offset, const std::string& what) const {
        throw Error(path_ + ": at byte offset " + std::to_string(offset) + ": " + what);
    }
    [[noreturn]] void failFile(const std::string& what) const { throw Error(path_ + ": " + what); }

    Grid read();

private:
    void parseMeta(const SectionEntry& s, Grid& g);
    std::string path_;
    std::vector<std::byte> d_;
};

Grid Reader::read() {
    const uint64_t size = d_.size();
    if (size < kGridHeaderBytes)
        failFile("truncated: " + std::to_string(size) + " bytes, a grid file header alone is " +
                 std::to_string(kGridHeaderBytes) + " (not a .hcg file?)");
    const std::byte* h = d_.data();
    if (std::memcmp(h, kMagic, 8) != 0) fail(0, "bad magic: not a heightcast grid (.hcg) file");
    auto major = get<uint16_t>(h + off::major);
    auto minor = get<uint16_t>(h + off::minor);
    if (major > kGridFileMajor)
        fail(off::major, "format version " + std::to_string(major) + "." + std::to_string(minor) +
                             " is newer than this reader (" + std::to_string(kGridFileMajor) + "." +
                             std::to_string(kGridFileMinor) + "); upgrade heightcast to read it");
    if (major != kGridFileMajor) fail(off::major, "unknown format version " + std::to_string(major));
    uint32_t storedHeaderCrc = get<uint32_t>(h + off::headerCrc);
    uint32_t headerCrc = crc32(std::span(h, off::headerCrc));
    if (storedHeaderCrc != headerCrc) fail(off::headerCrc, "header checksum mismatch (corrupt header)");
    if (get<uint32_t>(h + off::headerBytes) != kGridHeaderBytes)
        fail(off::headerBytes, "header size " + std::to_string(get<uint32_t>(h + off::headerBytes)) + " is not " +
                                   std::to_string(kGridHeaderBytes));
    uint64_t declared = get<uint64_t>(h + off::fileBytes);
    if (declared != size)
        fail(off::fileBytes, "header declares " + std::to_string(declared) + " bytes but the file has " +
                                 std::to_string(size) + (size < declared ? " (truncated)" : " (trailing data)"));
    for (size_t i = off::reserved; i < off::tableCrc; ++i)
        if (h[i] != std::byte{0}) fail(i, "reserved header byte is not zero");

    Grid g;
    g.stats = {};
    uint64_t cellCount = get<uint64_t>(h + off::cellCount);
    g.originWorldX = get<double>(h + off::originX);
    g.originWorldY = get<double>(h + off::originY);
    g.finestCellM = get<double>(h + off::finestCell);
    g.rootLevel = static_cast<int>(get<uint8_t>(h + off::rootLevel));
    g.minLevel = static_cast<int>(get<uint8_t>(h + off::minLevel));
    g.maxLevel = static_cast<int>(get<uint8_t>(h + off::maxLevel));
    unsigned layerCount = get<uint8_t>(h + off::layerCount);
    uint32_t sectionCount = get<uint32_t>(h + off::sectionCount);
    if (!std::isfinite(g.originWorldX) || !std::isfinite(g.originWorldY)) fail(off::originX, "origin is not finite");
    if (!(g.finestCellM > 0) || !std::isfinite(g.finestCellM)) fail(off::finestCell, "finest cell size is not a positive number");
    if (g.rootLevel > kMaxRootLevel) fail(off::rootLevel, "root level " + std::to_string(g.rootLevel) + " exceeds " + std::to_string(kMaxRootLevel));
    if (g.minLevel > g.maxLevel || g.maxLevel > g.rootLevel) fail(off::minLevel, "level range is inconsistent with the root level");
    if (layerCount < 1) fail(off::layerCount, "no layers (elevation is required)");
    if (cellCount > (size / 8)) fail(off::cellCount, "cell count " + std::to_string(cellCount) + " cannot fit in the file");

    uint64_t tableEnd = kGridHeaderBytes + uint64_t{sectionCount} * kGridSectionEntryBytes;
    if (sectionCount > 1024 || tableEnd > size) fail(off::sectionCount, "section table of " + std::to_string(sectionCount) + " entries runs past the end of the file");
    if (get<uint32_t>(h + off::tableCrc) != crc32(std::span(h + kGridHeaderBytes, tableEnd - kGridHeaderBytes)))
        fail(kGridHeaderBytes, "section table checksum mismatch (corrupt section table)");

    std::vector<SectionEntry> sections(sectionCount);
    uint64_t cursor = tableEnd;  // sections must follow one another in order, padding zero
    const SectionEntry* meta = nullptr;
    const SectionEntry* cells = nullptr;
    std::vector<const SectionEntry*> layerSec(layerCount, nullptr);
    for (uint32_t s = 0; s < sectionCount; ++s) {
        uint64_t at = kGridHeaderBytes + uint64_t{s} * kGridSectionEntryBytes;
        SectionEntry& e = sections[s];
        e.kind = get<uint32_t>(h + at);
        e.index = get<uint32_t>(h + at + 4);
        e.offset = get<uint64_t>(h + at + 8);
        e.bytes = get<uint64_t>(h + at + 16);
        e.crc = get<uint32_t>(h + at + 24);
        if (get<uint32_t>(h + at + 28) != 0) fail(at + 28, "reserved section-table field is not zero");
        if (e.offset % kGridSectionAlign != 0 || e.offset < cursor || e.offset > size || e.bytes > size - e.offset)
            fail(at + 8, "section " + std::to_string(s) + " (offset " + std::to_string(e.offset) + ", " +
                             std::to_string(e.bytes) + " bytes) is misplaced or runs past the end of the file");
        for (uint64_t p = cursor; p < e.offset; ++p)
            if (h[p] != std::byte{0}) fail(p, "padding byte is not zero");
        if (crc32(std::span(h + e.offset, e.bytes)) != e.crc)
            fail(e.offset, "checksum mismatch in section " + std::to_string(s) + " (corrupt data)");
        cursor = e.offset + e.bytes;
        if (e.kind == kMeta) {
            if (meta) fail(at, "two META sections");
            meta = &e;
        } else if (e.kind == kCells) {
            if (cells) fail(at, "two CELLS sections");
            if (e.bytes != cellCount * 8) fail(at + 16, "CELLS section holds " + std::to_string(e.bytes) + " bytes, expected " + std::to_string(cellCount * 8));
            cells = &e;
        } else if (e.kind == kLayer) {
            if (e.index >= layerCount || layerSec[e.index]) fail(at + 4, "LAYER section index " + std::to_string(e.index) + " is out of range or repeated");
            if (e.bytes != cellCount * 4) fail(at + 16, "LAYER section holds " + std::to_string(e.bytes) + " bytes, expected " + std::to_string(cellCount * 4));
            layerSec[e.index] = &e;
        } else if (minor <= kGridFileMinor) {
            fail(at, "unknown section kind " + std::to_string(e.kind));
        }  // else: a section a newer minor version added; skipped
    }
    for (uint64_t p = cursor; p < size; ++p)
        if (h[p] != std::byte{0}) fail(p, "trailing byte is not zero");
    if (!meta) failFile("no META section");
    if (!cells) failFile("no CELLS section");
    for (unsigned l = 0; l < layerCount; ++l)
        if (!layerSec[l]) failFile("no LAYER section for layer " + std::to_string(l));

    g.layers.assign(layerCount, LayerInfo{});
    parseMeta(*meta, g);
    g.codes.resize(cellCount);
    std::memcpy(g.codes.data(), h + cells->offset, cells->bytes);
    g.values.assign(layerCount, {});
    for (unsigned l = 0; l < layerCount; ++l) {
        g.values[l].resize(cellCount);
        std::memcpy(g.values[l].data(), h + layerSec[l]->offset, layerSec[l]->bytes);
    }
    std::string problem = g.validate();
    if (!problem.empty()) fail(cells->offset, "invalid grid: " + problem);
    if (g.structureHash() != get<uint64_t>(h + off::structureHash)) fail(off::structureHash, "structure hash does not match the cells");
    if (g.contentHash() != get<uint64_t>(h + off::contentHash)) fail(off::contentHash, "content hash does not match the cells and values");
    return g;
}

void Reader::parseMeta(const SectionEntry& s, Grid& g) {
    std::map<std::string, std::string> kv;
    uint64_t p = s.offset, end = s.offset + s.bytes;
    auto readString = [&](std::string& out) {
        if (end - p < 4) fail(p, "META record is truncated");
        uint32_t n = get<uint32_t>(d_.data() + p);
        p += 4;
        if (n > end - p) fail(p - 4, "META string of " + std::to_string(n) + " bytes runs past its section");
        out.assign(reinterpret_cast<const char*>(d_.data() + p), n);
        p += n;
    };
    while (p < end) {
        uint64_t at = p;
        std::string k, v;
        readString(k);
        readString(v);
        if (!kv.emplace(k, v).second) fail(at, "META key '" + k + "' appears twice");
    }
    auto need = [&](const std::string& k) -> const std::string& {
        auto it = kv.find(k);
        if (it == kv.end()) fail(s.offset, "META lacks the key '" + k + "'");
        return it->second;
    };
    auto number = [&](const std::string& k, auto& out) {
        auto it = kv.find(k);
        if (it == kv.end()) return;  // ingest statistics are optional
        auto r = std::from_chars(it->second.data(), it->second.data() + it->second.size(), out);
        if (r.ec != std::errc() || r.ptr != it->second.data() + it->second.size())
            fail(s.offset, "META value of '" + k + "' is not a number: '" + it->second + "'");
    };
    g.crsWkt = need("crs_wkt");
    for (size_t l = 0; l < g.layers.size(); ++l) {
        g.layers[l].name = need("layer." + std::to_string(l) + ".name");
        g.layers[l].units = need("layer." + std::to_string(l) + ".units");
    }
    if (kv.count("ingest.source")) g.stats.sourcePath = kv["ingest.source"];
    if (kv.count("ingest.source_crs")) g.stats.sourceCrsName = kv["ingest.source_crs"];
    number("ingest.source_width", g.stats.sourceWidth);
    number("ingest.source_height", g.stats.sourceHeight);
    number("ingest.valid_pixels", g.stats.validPixels);
    number("ingest.tolerance_m", g.stats.toleranceM);
    number("ingest.max_dev_m", g.stats.maxDevM);
    number("ingest.rms_dev_m", g.stats.rmsDevM);
    number("ingest.seconds", g.stats.seconds);
}

}  // namespace

struct GridFileWriter::Impl {
    Impl(std::string path, const Grid& gridShape, uint64_t cells)
        : out(std::move(path)), shape(gridShape), cellCount(cells), check(shape), hasher(shape, cells) {}
    AtomicFileWriter out;
    Grid shape;  // geometry, CRS and layers; no cells
    uint64_t cellCount;
    CellStreamCheck check;
    GridHasher hasher;
    std::vector<SectionEntry> sections;  // CELLS, LAYER 0..L-1; META is appended at commit
    uint64_t written = 0;
    uint64_t dataEnd = 0;
};

GridFileWriter::GridFileWriter(const std::string& path, const Grid& shape, uint64_t cellCount) {
    std::string problem = shape.validateShape();
    if (!problem.empty()) throw Error(path + ": refusing to write an invalid grid: " + problem);
    Grid bare;  // copy the shape only, never its cells
    bare.originWorldX = shape.originWorldX;
    bare.originWorldY = shape.originWorldY;
    bare.finestCellM = shape.finestCellM;
    bare.rootLevel = shape.rootLevel;
    bare.minLevel = shape.minLevel;
    bare.maxLevel = shape.maxLevel;
    bare.crsWkt = shape.crsWkt;
    bare.layers = shape.layers;
    bare.values.assign(shape.layers.size(), {});
    impl_ = std::make_unique<Impl>(path, bare, cellCount);
    // Layout: header, table, CELLS, LAYER..., META (last: its statistics are known only at the end).
    uint64_t cursor = kGridHeaderBytes + (shape.layers.size() + 2) * kGridSectionEntryBytes;
    auto place = [&](uint32_t kind, uint32_t index, uint64_t bytes) {
        uint64_t at = alignUp(cursor);
        impl_->sections.push_back({kind, index, at, bytes, 0});
        cursor = at + bytes;
    };
    place(kCells, 0, cellCount * 8);
    for (size_t l = 0; l < shape.layers.size(); ++l) place(kLayer, static_cast<uint32_t>(l), cellCount * 4);
    impl_->dataEnd = cursor;
}

GridFileWriter::~GridFileWriter() = default;

void GridFileWriter::append(std::span<const uint64_t> codes, const std::vector<std::span<const float>>& layerValues) {
    Impl& w = *impl_;
    const size_t layers = w.shape.layers.size();
    if (layerValues.size() != layers) throw Error(w.out.path() + ": " + std::to_string(layerValues.size()) + " value arrays for " + std::to_string(layers) + " layers");
    for (const auto& v : layerValues)
        if (v.size() != codes.size()) throw Error(w.out.path() + ": layer values and cells differ in number");
    if (codes.size() > w.cellCount - w.written) throw Error(w.out.path() + ": more cells than the " + std::to_string(w.cellCount) + " announced");
    float v[256];
    for (size_t i = 0; i < codes.size(); ++i) {
        for (size_t l = 0; l < layers; ++l) v[l] = layerValues[l][i];
        std::string problem = w.check.next(codes[i], v);
        if (!problem.empty()) throw Error(w.out.path() + ": refusing to write an invalid grid: " + problem);
    }
    SectionEntry& cells = w.sections[0];
    auto codeBytes = std::as_bytes(codes);
    w.out.writeAt(cells.offset + w.written * 8, codeBytes);
    cells.crc = crc32(codeBytes, cells.crc);
    w.hasher.addCodes(codes);
    for (size_t l = 0; l < layers; ++l) {
        SectionEntry& s = w.sections[1 + l];
        auto bytes = std::as_bytes(layerValues[l]);
        w.out.writeAt(s.offset + w.written * 4, bytes);
        s.crc = crc32(bytes, s.crc);
        w.hasher.addValues(l, layerValues[l]);
    }
    w.written += codes.size();
}

void GridFileWriter::commit(const IngestStats& stats) {
    Impl& w = *impl_;
    if (w.written != w.cellCount)
        throw Error(w.out.path() + ": " + std::to_string(w.written) + " cells written of " + std::to_string(w.cellCount) + " announced");
    w.shape.stats = stats;
    std::vector<std::byte> meta = encodeMeta(w.shape);
    const uint64_t metaAt = alignUp(w.dataEnd);
    w.sections.push_back({kMeta, 0, metaAt, meta.size(), crc32(meta)});
    const uint64_t fileBytes = metaAt + meta.size();
    // Zero padding between sections (the file is sparse until then).
    uint64_t cursor = kGridHeaderBytes + w.sections.size() * kGridSectionEntryBytes;
    std::vector<std::byte> zeros(kGridSectionAlign, std::byte{0});
    for (const auto& s : w.sections) {
        if (s.offset > cursor) w.out.writeAt(cursor, std::span(zeros).first(s.offset - cursor));
        cursor = s.offset + s.bytes;
    }
    w.out.writeAt(metaAt, meta);

    const Grid& g = w.shape;
    std::vector<std::byte> head(kGridHeaderBytes + w.sections.size() * kGridSectionEntryBytes, std::byte{0});
    std::memcpy(head.data(), kMagic, 8);
    put(head, off::major, kGridFileMajor);
    put(head, off::minor, kGridFileMinor);
    put(head, off::headerBytes, kGridHeaderBytes);
    put(head, off::fileBytes, fileBytes);
    put(head, off::cellCount, w.cellCount);
    put(head, off::originX, g.originWorldX);
    put(head, off::originY, g.originWorldY);
    put(head, off::finestCell, g.finestCellM);
    put(head, off::rootLevel, static_cast<uint8_t>(g.rootLevel));
    put(head, off::minLevel, static_cast<uint8_t>(g.minLevel));
    put(head, off::maxLevel, static_cast<uint8_t>(g.maxLevel));
    put(head, off::layerCount, static_cast<uint8_t>(g.layers.size()));
    put(head, off::sectionCount, static_cast<uint32_t>(w.sections.size()));
    put(head, off::contentHash, w.hasher.contentHash());
    put(head, off::structureHash, w.hasher.structureHash());
    for (size_t s = 0; s < w.sections.size(); ++s) {
        size_t at = kGridHeaderBytes + s * kGridSectionEntryBytes;
        put(head, at, w.sections[s].kind);
        put(head, at + 4, w.sections[s].index);
        put(head, at + 8, w.sections[s].offset);
        put(head, at + 16, w.sections[s].bytes);
        put(head, at + 24, w.sections[s].crc);
    }
    put(head, off::tableCrc, crc32(std::span(head).subspan(kGridHeaderBytes)));
    put(head, off::headerCrc, crc32(std::span(head).first(off::headerCrc)));
    w.out.writeAt(0, head);
    w.out.commit();
}

void writeGrid(const Grid& g, const std::string& path) {
    std::string problem = g.validate();
    if (!problem.empty()) throw Error(path + ": refusing to write an invalid grid: " + problem);
    GridFileWriter w(path, g, g.cellCount());
    std::vector<std::span<const float>> values;
    for (const auto& v : g.values) values.emplace_back(v);
    w.append(g.codes, values);
    w.commit(g.stats);
}

Grid readGrid(const std::string& path) {
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) throw Error(path + ": no such file");
    if (std::filesystem::is_directory(path, ec)) throw Error(path + ": is a directory, not a grid file");
    std::ifstream in(path, std::ios::binary | std::ios::ate);
    if (!in) throw Error(path + ": cannot open for reading");
    auto size = static_cast<size_t>(in.tellg());
    std::vector<std::byte> data(size);
    in.seekg(0);
    if (size > 0 && !in.read(reinterpret_cast<char*>(data.data()), static_cast<std::streamsize>(size)))
        throw Error(path + ": read failed");
    return Reader(path, std::move(data)).read();
}

}  // namespace hc
