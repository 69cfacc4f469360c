// heightcast/core/ranks.h: the processes of one preprocessing run (docs/design.md section 7).
//
// Started by `mpirun -np N`, hc-ingest and hc-influence run as N ranks that split the work; rank 0 opens and commits
// each output file, and the ranks write their shares into it in place (GridFilePart, on_ranks.h's writers over
// SectionedFilePart) or send them to rank 0: the same bytes as one process writes. Started without mpirun, a tool is
// rank 0 of 1 and every call here is a no-op or the identity: nothing changes.
//
// Failures: a rank's exception inside together() reaches every rank as the same RanksError (the first failing rank's
// message), so all ranks stop at the same point, rank 0 says it once, its atomic writers remove their temporaries,
// and every process exits non-zero; nobody waits forever for a rank that gave up.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <functional>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

#include "heightcast/core/error.h"

namespace hc::ranks {

// An error every rank raised together (together()): rank 0 reports it, the others stay quiet.
class RanksError : public Error {
public:
    using Error::Error;
};

// Starts MPI when this process was started by mpirun (OMPI_COMM_WORLD_SIZE, PMI_SIZE or PMIX_RANK in the
// environment) and the build has MPI; ends it at destruction. One per process, in main(). Throws hc::Error for a
// run under mpirun with several processes in a build without MPI (HC_WITH_MPI=OFF): each would do all the work.
class Session {
public:
    Session(int& argc, char**& argv);
    ~Session();
    Session(const Session&) = delete;
    Session& operator=(const Session&) = delete;
};

int rank();   // K: 0 .. count() - 1
int count();  // N: 1 without mpirun
bool builtWithMpi();
inline bool distributed() { return count() > 1; }
// "rank K/N" (1-based K, as the logs print it).
std::string name();

// Every rank calls it with its own error message ("" = none); every rank gets the first failing rank's message,
// prefixed with that rank's name when there are several ranks, or "" when none failed.
std::string agree(const std::string& error);

// Runs fn on every rank; if it throws on any, every rank throws RanksError with the first failing rank's message.
// Calls nest: a rank that fails inside fn skips to the next agreement point, which matches the one the other ranks
// reach next (any together() or agree()), so between two agreement points a rank may only compute and send.
void together(const std::function<void()>& fn);

// Stops every rank at once (MPI_Abort) after an error only this rank saw outside together(); returns only without MPI.
void abortAll(int status);

// Point to point, any size (chunked below MPI's int counts): a rank other than 0 sends, rank 0 receives from
// `from`, in the order the sender sent.
void sendToRoot(std::span<const std::byte> bytes);
std::vector<std::byte> receiveFrom(int from);
// The same into memory the caller holds (no copy): the message must be exactly out.size() bytes (hc::Error otherwise).
void receiveInto(int from, std::span<std::byte> out);

// Every rank's bytes, on every rank, index = rank (meant for small tables: per-tile summaries, counts).
std::vector<std::vector<std::byte>> allGather(std::span<const std::byte> bytes);

// Typed helpers over the byte calls, for trivially copyable element types.
template <typename T>
void sendToRoot(const std::vector<T>& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    sendToRoot(std::as_bytes(std::span<const T>(v)));
}
template <typename T>
std::vector<T> receiveVectorFrom(int from) {
    static_assert(std::is_trivially_copyable_v<T>);
    const std::vector<std::byte> b = receiveFrom(from);
    if (b.size() % sizeof(T) != 0)
        throw Error("rank message of " + std::to_string(b.size()) + " bytes is no whole number of items");
    std::vector<T> out(b.size() / sizeof(T));
    if (!b.empty()) std::memcpy(out.data(), b.data(), b.size());
    return out;
}
template <typename T>
std::vector<std::vector<T>> allGatherVectors(const std::vector<T>& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    const auto all = allGather(std::as_bytes(std::span<const T>(v)));
    std::vector<std::vector<T>> out(all.size());
    for (size_t r = 0; r < all.size(); ++r) {
        out[r].resize(all[r].size() / sizeof(T));
        if (!all[r].empty()) std::memcpy(out[r].data(), all[r].data(), out[r].size() * sizeof(T));
    }
    return out;
}

// One line on stderr prefixed with name(), e.g. "hc-influence: rank 2/3: 41 tiles, 1.2 M cells, 3.4 s". Silent on
// one process.
void log(const char* program, const std::string& line);

// The contiguous share [begin, end) of `total` items rank `r` of `n` takes: as equal as integers allow.
inline uint64_t shareBegin(uint64_t total, int r, int n) {
    const uint64_t q = total / uint64_t(n), rem = total % uint64_t(n);  // floor(total r / n) without overflow
    return q * uint64_t(r) + rem * uint64_t(r) / uint64_t(n);
}

}  // namespace hc::ranks
