// heightcast/support/cli.h: self-describing command-line options (name, value, help with units and default),
// shared by every heightcast tool so they parse, validate and explain themselves the same way.
#pragma once

#include <array>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace hc::cli {

class Parser {
public:
    Parser(std::string program, std::string synopsis, std::string description);

    // A switch without a value.
    void flag(const std::string& name, const std::string& help, bool& target);
    // An option with a value; `help` states the units and the default.
    void option(const std::string& name, const std::string& value, const std::string& help, std::string& target);
    void option(const std::string& name, const std::string& value, const std::string& help, double& target);
    void option(const std::string& name, const std::string& value, const std::string& help,
                std::optional<double>& target);
    void option(const std::string& name, const std::string& value, const std::string& help, int& target);
    void option(const std::string& name, const std::string& value, const std::string& help, unsigned& target);
    // A positional argument.
    void positional(const std::string& name, const std::string& help, std::string& target);
    // Options that may not be given together (the first given one wins nothing: it is an error).
    void exclusive(std::vector<std::string> names);

    // Parses argv. On --help prints help() to stdout and returns false (the tool exits 0).
    // Throws hc::Error for unknown options, missing values, bad numbers, missing positionals.
    bool parse(int argc, char** argv);
    bool given(const std::string& name) const;
    std::string help() const;

private:
    struct Opt {
        std::string name, value, help;
        std::function<void(const std::string&)> set;  // empty value for flags
        bool isFlag = false;
        bool seen = false;
    };
    struct Pos {
        std::string name, help;
        std::string* target;
    };
    Opt* find(const std::string& name);
    std::string program_, synopsis_, description_;
    std::vector<Opt> opts_;
    std::vector<Pos> pos_;
    std::vector<std::vector<std::string>> exclusive_;
};

// Parses a finite double; throws hc::Error naming `what`.
double parseNumber(const std::string& text, const std::string& what);
// Parses "A,B,C..." into minCount..maxCount finite doubles; throws hc::Error naming `what`.
std::vector<double> parseNumberList(const std::string& text, const std::string& what, size_t minCount, size_t maxCount);

// A list of files: "A,B,C" in that order, and any element holding a glob pattern (* ? [) replaced by its matches in
// natural order (depth_2 before depth_10). Throws hc::Error naming `what` when a pattern matches nothing.
std::vector<std::string> expandFileList(const std::string& text, const std::string& what);

// Probe points: CSV text whose first line starts with x,y, then one "x,y[,more columns]" line per point
// (finite numbers; blank lines skipped; CRLF accepted). Errors are "NAME: line N: problem". Throws hc::Error.
std::vector<std::array<double, 2>> parsePointsCsv(std::string_view text, const std::string& name);
// Reads the file `path` and parses it with parsePointsCsv. Throws hc::Error.
std::vector<std::array<double, 2>> readPointsCsv(const std::string& path);

// Runs a tool's body: hc::Error and other failures become "PROGRAM: error: MESSAGE" on stderr and
// exit status 1. Returns the process exit status.
int run(const char* program, const std::function<int()>& body);

// Throws hc::Error unless `path`'s directory exists and `path` is neither a directory nor another
// non-regular file (a device, a pipe) that an atomic rename would replace.
void checkWritable(const std::string& path, const std::string& what);
// Throws hc::Error if `output` names the same file as `input` (through any path or link).
void checkNotSame(const std::string& output, const std::string& input, const std::string& what);

}  // namespace hc::cli
