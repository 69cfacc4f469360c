#include "heightcast/support/cli.h"

#include <glob.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <new>
#include <sstream>

#include "heightcast/core/error.h"

namespace hc::cli {

Parser::Parser(std::string program, std::string synopsis, std::string description)
    : program_(std::move(program)), synopsis_(std::move(synopsis)), description_(std::move(description)) {}

void Parser::flag(const std::string& name, const std::string& help, bool& target) {
    opts_.push_back({name, "", help, [&target](const std::string&) { target = true; }, true});
}
void Parser::option(const std::string& name, const std::string& value, const std::string& help, std::string& target) {
    opts_.push_back({name, value, help, [&target](const std::string& v) { target = v; }});
}
void Parser::option(const std::string& name, const std::string& value, const std::string& help, double& target) {
    opts_.push_back({name, value, help, [&target, name](const std::string& v) { target = parseNumber(v, name); }});
}
void Parser::option(const std::string& name, const std::string& value, const std::string& help,
                    std::optional<double>& target) {
    opts_.push_back({name, value, help, [&target, name](const std::string& v) { target = parseNumber(v, name); }});
}
void Parser::option(const std::string& name, const std::string& value, const std::string& help, int& target) {
    opts_.push_back({name, value, help, [&target, name](const std::string& v) {
                         double d = parseNumber(v, name);
                         if (d != std::floor(d) || std::abs(d) > 1e9) throw Error(name + " " + v + ": not an integer");
                         target = static_cast<int>(d);
                     }});
}
void Parser::option(const std::string& name, const std::string& value, const std::string& help, unsigned& target) {
    opts_.push_back({name, value, help, [&target, name](const std::string& v) {
                         double d = parseNumber(v, name);
                         if (d != std::floor(d) || d < 0 || d > 4096)
                             throw Error(name + " " + v + ": not a count in 0..4096");
                         target = static_cast<unsigned>(d);
                     }});
}
void Parser::positional(const std::string& name, const std::string& help, std::string& target) {
    pos_.push_back({name, help, &target});
}
void Parser::exclusive(std::vector<std::string> names) { exclusive_.push_back(std::move(names)); }

Parser::Opt* Parser::find(const std::string& name) {
    for (auto& o : opts_)
        if (o.name == name) return &o;
    return nullptr;
}

bool Parser::given(const std::string& name) const {
    for (const auto& o : opts_)
        if (o.name == name) return o.seen;
    return false;
}

bool Parser::parse(int argc, char** argv) {
    size_t nextPos = 0;
    for (int i = 1; i < argc; ++i) {
        std::string a = argv[i];
        if (a == "--help" || a == "-h") {
            std::fputs(help().c_str(), stdout);
            return false;
        }
        if (a.size() > 1 && a[0] == '-' &&
            !(a.size() > 1 && (std::isdigit(static_cast<unsigned char>(a[1])) || a[1] == '.'))) {
            std::string value;
            bool inlineValue = false;
            if (auto eq = a.find('='); eq != std::string::npos && a.rfind("--", 0) == 0) {
                value = a.substr(eq + 1);
                a = a.substr(0, eq);
                inlineValue = true;
            }
            Opt* o = find(a);
            if (!o) throw Error("unknown option " + a + " (see --help)");
            if (o->seen) throw Error(a + " given twice");
            o->seen = true;
            if (o->isFlag) {
                if (inlineValue) throw Error(a + " takes no value");
                o->set("");
                continue;
            }
            if (!inlineValue) {
                if (i + 1 >= argc) throw Error(a + " needs a value: " + a + " " + o->value);
                value = argv[++i];
            }
            o->set(value);
            continue;
        }
        if (nextPos >= pos_.size()) throw Error("unexpected argument '" + a + "' (see --help)");
        *pos_[nextPos++].target = a;
    }
    if (nextPos < pos_.size()) throw Error("missing " + pos_[nextPos].name + " (see --help)");
    for (const auto& group : exclusive_) {
        std::vector<std::string> seen;
        for (const auto& n : group)
            if (given(n)) seen.push_back(n);
        if (seen.size() > 1) throw Error(seen[0] + " and " + seen[1] + " cannot be combined");
    }
    return true;
}

std::string Parser::help() const {
    std::ostringstream s;
    s << "usage: " << program_ << " " << synopsis_ << "\n\n" << description_ << "\n";
    if (!pos_.empty()) {
        s << "\narguments:\n";
        for (const auto& p : pos_) s << "  " << p.name << "\n      " << p.help << "\n";
    }
    s << "\noptions:\n";
    for (const auto& o : opts_) {
        s << "  " << o.name;
        if (!o.isFlag) s << " " << o.value;
        s << "\n      " << o.help << "\n";
    }
    s << "  --help\n      print this help and exit\n";
    return s.str();
}

double parseNumber(const std::string& text, const std::string& what) {
    double v = 0;
    const char* b = text.data();
    const char* e = b + text.size();
    auto r = std::from_chars(b, e, v);
    if (text.empty() || r.ec != std::errc() || r.ptr != e || !std::isfinite(v))
        throw Error(what + " " + text + ": not a finite number");
    return v;
}

std::vector<double> parseNumberList(const std::string& text, const std::string& what, size_t minCount,
                                    size_t maxCount) {
    std::vector<double> v;
    size_t start = 0;
    for (;;) {
        const size_t comma = text.find(',', start);
        v.push_back(
            parseNumber(text.substr(start, comma == std::string::npos ? std::string::npos : comma - start), what));
        if (comma == std::string::npos) break;
        start = comma + 1;
    }
    if (v.size() < minCount || v.size() > maxCount)
        throw Error(what + " " + text + ": expected " + (maxCount == SIZE_MAX ? "at least " : "") +
                    std::to_string(minCount) +
                    (maxCount > minCount && maxCount != SIZE_MAX ? " or " + std::to_string(maxCount) : "") +
                    " comma-separated numbers");
    return v;
}

namespace {

// Natural order: runs of digits compare as numbers, so step_9 comes before step_10.
bool naturalLess(const std::string& a, const std::string& b) {
    size_t i = 0, j = 0;
    while (i < a.size() && j < b.size()) {
        if (std::isdigit(static_cast<unsigned char>(a[i])) && std::isdigit(static_cast<unsigned char>(b[j]))) {
            size_t ie = i, je = j;
            while (ie < a.size() && std::isdigit(static_cast<unsigned char>(a[ie]))) ++ie;
            while (je < b.size() && std::isdigit(static_cast<unsigned char>(b[je]))) ++je;
            std::string_view x(a.data() + i, ie - i), y(b.data() + j, je - j);
            while (x.size() > 1 && x[0] == '0') x.remove_prefix(1);
            while (y.size() > 1 && y[0] == '0') y.remove_prefix(1);
            if (x.size() != y.size()) return x.size() < y.size();
            if (x != y) return x < y;
            i = ie, j = je;
        } else {
            if (a[i] != b[j]) return a[i] < b[j];
            ++i, ++j;
        }
    }
    return a.size() - i < b.size() - j;
}

}  // namespace

std::vector<std::string> expandFileList(const std::string& text, const std::string& what) {
    std::vector<std::string> out;
    size_t start = 0;
    for (;;) {
        const size_t comma = text.find(',', start);
        const std::string item = text.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
        if (item.empty()) throw Error(what + " " + text + ": an empty file name in the list");
        if (item.find_first_of("*?[") == std::string::npos) {
            out.push_back(item);
        } else {
            glob_t g{};
            const int rc = ::glob(item.c_str(), 0, nullptr, &g);
            std::vector<std::string> matches;
            for (size_t k = 0; rc == 0 && k < g.gl_pathc; ++k) matches.emplace_back(g.gl_pathv[k]);
            globfree(&g);
            if (matches.empty()) throw Error(what + " " + item + ": the pattern matches no file");
            std::sort(matches.begin(), matches.end(), naturalLess);
            out.insert(out.end(), matches.begin(), matches.end());
        }
        if (comma == std::string::npos) break;
        start = comma + 1;
    }
    return out;
}

std::vector<std::array<double, 2>> parsePointsCsv(std::string_view text, const std::string& name) {
    if (text.empty()) throw Error(name + ": empty file (expected a header line x,y)");
    // A hostile line may be megabytes long: quote only its start in a message.
    auto quoted = [](std::string_view line) {
        constexpr size_t kMaxQuoted = 80;
        return "'" + std::string(line.substr(0, kMaxQuoted)) + (line.size() > kMaxQuoted ? "...'" : "'");
    };
    std::vector<std::array<double, 2>> pts;
    size_t lineNo = 0, start = 0;
    while (start < text.size()) {  // lines end at '\n'; a last line may lack one
        const size_t nl = text.find('\n', start);
        std::string_view line = text.substr(start, nl == std::string_view::npos ? std::string_view::npos : nl - start);
        start = nl == std::string_view::npos ? text.size() : nl + 1;
        ++lineNo;
        if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
        if (lineNo == 1) {
            if (line.substr(0, 3) != "x,y")
                throw Error(name + ": line 1: header must start with x,y (got " + quoted(line) + ")");
            continue;
        }
        if (line.empty()) continue;
        std::array<double, 2> p{};
        const char* b = line.data();
        const char* e = b + line.size();
        auto r1 = std::from_chars(b, e, p[0]);
        bool ok = r1.ec == std::errc() && r1.ptr < e && *r1.ptr == ',';
        if (ok) {
            auto r2 = std::from_chars(r1.ptr + 1, e, p[1]);
            ok = r2.ec == std::errc() && (r2.ptr == e || *r2.ptr == ',');
        }
        if (!ok || !std::isfinite(p[0]) || !std::isfinite(p[1]))
            throw Error(name + ": line " + std::to_string(lineNo) + ": expected two numbers x,y, got " + quoted(line));
        pts.push_back(p);
    }
    return pts;
}

std::vector<std::array<double, 2>> readPointsCsv(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw Error(path + ": cannot open for reading");
    std::ostringstream text;
    text << in.rdbuf();
    return parsePointsCsv(text.str(), path);
}

int run(const char* program, const std::function<int()>& body) {
    try {
        return body();
    } catch (const Error& e) {
        std::fprintf(stderr, "%s: error: %s\n", program, e.what());
    } catch (const std::bad_alloc&) {
        std::fprintf(stderr, "%s: error: out of memory\n", program);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "%s: error: %s\n", program, e.what());
    }
    return 1;
}

void checkNotSame(const std::string& output, const std::string& input, const std::string& what) {
    std::error_code ec;
    if (std::filesystem::equivalent(output, input, ec))
        throw Error(output + ": " + what + " would overwrite the input " + input);
}

void checkWritable(const std::string& path, const std::string& what) {
    namespace fs = std::filesystem;
    std::error_code ec;
    fs::path p(path);
    if (p.filename().empty()) throw Error(path + ": " + what + " must name a file");
    if (fs::is_directory(p, ec)) throw Error(path + ": is a directory (" + what + ")");
    if (fs::exists(p, ec) && !fs::is_regular_file(p, ec))
        throw Error(path + ": exists and is not a regular file (" + what + "); it would be replaced");
    fs::path dir = p.parent_path();
    if (!dir.empty() && !fs::is_directory(dir, ec))
        throw Error(path + ": directory " + dir.string() + " does not exist (" + what + ")");
}

}  // namespace hc::cli
