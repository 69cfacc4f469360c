// bench/bench_common.h: what every benchmark program shares: the machine's load and free memory, a list option, and
// running one measurement in a forked child so that its peak RSS (getrusage) is its own. Benchmarks format
// with fmt::format and time with hc::Stopwatch.
#pragma once

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <string>
#include <type_traits>
#include <vector>

#include <fmt/format.h>

#include "heightcast/core/error.h"

namespace hc::bench {

// The 1-minute load average: the machine may be shared, and a busy core shows up in every time here.
inline std::string loadAverage() {
    double one = -1;
    if (FILE* f = std::fopen("/proc/loadavg", "r")) {
        if (std::fscanf(f, "%lf", &one) != 1) one = -1;
        std::fclose(f);
    }
    return one < 0 ? "unknown" : fmt::format("{:.2f}", one);
}

// Bytes this process could still allocate without pushing the machine into swap or the OOM killer: the kernel's
// MemAvailable (/proc/meminfo), or less where an address-space limit (ulimit -v) leaves less above the
// process's current virtual size. 0 if /proc cannot be read.
inline uint64_t memoryAvailableBytes() {
    auto fieldKb = [](const char* path, const char* key) -> uint64_t {
        FILE* f = std::fopen(path, "r");
        if (!f) return 0;
        char line[256];
        uint64_t kb = 0;
        const size_t keyLength = std::strlen(key);
        while (std::fgets(line, sizeof line, f))
            if (std::strncmp(line, key, keyLength) == 0) {
                kb = std::strtoull(line + keyLength, nullptr, 10);
                break;
            }
        std::fclose(f);
        return kb;
    };
    uint64_t available = fieldKb("/proc/meminfo", "MemAvailable:") * 1024;
    rlimit limit{};
    if (getrlimit(RLIMIT_AS, &limit) == 0 && limit.rlim_cur != RLIM_INFINITY) {
        const uint64_t used = fieldKb("/proc/self/status", "VmSize:") * 1024;
        available = std::min<uint64_t>(available, limit.rlim_cur > used ? limit.rlim_cur - used : 0);
    }
    return available;
}

// "a,b,c" -> {"a", "b", "c"}; an empty entry is an error naming `what`.
inline std::vector<std::string> splitList(const std::string& text, const std::string& what) {
    std::vector<std::string> out;
    size_t at = 0;
    while (at <= text.size()) {
        size_t comma = std::min(text.find(',', at), text.size());
        out.push_back(text.substr(at, comma - at));
        if (out.back().empty())
            throw hc::Error(what + " '" + text + "': empty entry (give a list separated by commas)");
        at = comma + 1;
    }
    return out;
}

// Runs body(result) in a forked child and returns the result, or throws hc::Error with the child's
// own error message (or how it died). Result must be trivially copyable (it crosses a pipe).
template <typename Result>
Result inChild(const std::string& what, const std::function<void(Result&)>& body) {
    struct Envelope {
        Result result{};
        char error[512] = {};
    };
    static_assert(std::is_trivially_copyable_v<Envelope>);
    int fds[2];
    if (pipe(fds) != 0) throw hc::Error(std::string("pipe: ") + std::strerror(errno));
    std::fflush(nullptr);  // or the child would flush the parent's pending output a second time
    pid_t pid = fork();
    if (pid < 0) throw hc::Error(std::string("fork: ") + std::strerror(errno));
    if (pid == 0) {
        close(fds[0]);
        Envelope env;
        try {
            body(env.result);
        } catch (const std::exception& e) {
            std::snprintf(env.error, sizeof env.error, "%s", e.what());
        }
        ssize_t written = write(fds[1], &env, sizeof env);
        _exit(written == static_cast<ssize_t>(sizeof env) ? 0 : 1);  // no atexit, no parent destructors
    }
    close(fds[1]);
    Envelope env;
    size_t got = 0;
    while (got < sizeof env) {
        ssize_t n = read(fds[0], reinterpret_cast<char*>(&env) + got, sizeof env - got);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) break;
        got += static_cast<size_t>(n);
    }
    close(fds[0]);
    int status = 0;
    while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
    }
    if (WIFSIGNALED(status))
        throw hc::Error(what + ": child process killed by signal " + std::to_string(WTERMSIG(status)) +
                        (WTERMSIG(status) == SIGKILL ? " (out of memory?)" : ""));
    if (got != sizeof env) throw hc::Error(what + ": child process exited without a result");
    if (env.error[0]) throw hc::Error(what + ": " + env.error);
    return env.result;
}

}  // namespace hc::bench
