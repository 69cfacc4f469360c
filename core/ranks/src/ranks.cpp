// The ranks of one run (ranks.h): OpenMPI where the build has it (HC_WITH_MPI), one process otherwise.
#include "heightcast/core/ranks.h"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <limits>

#if HC_WITH_MPI
#include <mpi.h>
#endif

namespace hc::ranks {

namespace {

int gRank = 0, gCount = 1;
bool gStarted = false;

// Started by a launcher (OpenMPI's mpirun, or another PMI / PMIx one)?
int launcherSize() {
    for (const char* var : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_SIZE"})
        if (const char* v = std::getenv(var); v && *v) return std::max(1, std::atoi(v));
    return std::getenv("PMIX_RANK") ? 2 : 1;  // PMIx without a size: treat as several (checked by MPI itself)
}

#if HC_WITH_MPI
constexpr size_t kChunk = size_t{1} << 28;  // bytes a message: far below INT_MAX
constexpr int kTagSize = 1, kTagData = 2;

void check(int rc, const char* what) {
    if (rc != MPI_SUCCESS) throw Error(std::string("MPI: ") + what + " failed");
}
#endif

}  // namespace

Session::Session(int& argc, char**& argv) {
    const int launched = launcherSize();
#if HC_WITH_MPI
    if (launched > 1 || std::getenv("OMPI_COMM_WORLD_SIZE")) {
        check(MPI_Init(&argc, &argv), "MPI_Init");
        gStarted = true;
        MPI_Comm_rank(MPI_COMM_WORLD, &gRank);
        MPI_Comm_size(MPI_COMM_WORLD, &gCount);
    }
#else
    (void)argc, (void)argv;
    if (launched > 1)
        throw Error(
            "started by mpirun with " + std::to_string(launched) +
            " processes, but this build has no MPI (HC_WITH_MPI=OFF or no MPI found): each process would do all "
            "the work; run one process, or rebuild with libopenmpi-dev installed");
#endif
}

Session::~Session() {
#if HC_WITH_MPI
    if (gStarted) MPI_Finalize();
#endif
    gStarted = false;
    gRank = 0, gCount = 1;
}

int rank() { return gRank; }
int count() { return gCount; }
bool builtWithMpi() {
#if HC_WITH_MPI
    return true;
#else
    return false;
#endif
}

std::string name() { return "rank " + std::to_string(gRank + 1) + "/" + std::to_string(gCount); }

std::string agree(const std::string& error) {
    if (gCount == 1) return error;
#if HC_WITH_MPI
    // The lowest failing rank speaks: a min-reduction over (failed ? rank : N), then that rank broadcasts its message.
    const int mine = error.empty() ? gCount : gRank;
    int first = gCount;
    check(MPI_Allreduce(&mine, &first, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD), "MPI_Allreduce");
    if (first == gCount) return {};
    int length = first == gRank ? int(std::min<size_t>(error.size(), 4096)) : 0;
    check(MPI_Bcast(&length, 1, MPI_INT, first, MPI_COMM_WORLD), "MPI_Bcast");
    std::string text(size_t(length), '\0');
    if (first == gRank) text.assign(error, 0, size_t(length));
    if (length > 0) check(MPI_Bcast(text.data(), length, MPI_CHAR, first, MPI_COMM_WORLD), "MPI_Bcast");
    return "rank " + std::to_string(first + 1) + "/" + std::to_string(gCount) + ": " + text;
#else
    return error;
#endif
}

void together(const std::function<void()>& fn) {
    std::string error;
    try {
        fn();
    } catch (const RanksError&) {
        throw;  // agreed already, by a together() inside fn: every rank is here with it
    } catch (const std::bad_alloc&) {
        error = "out of memory";
    } catch (const std::exception& e) {
        error = e.what();
        if (error.empty()) error = "failed";
    }
    if (gCount == 1) {
        if (!error.empty()) throw RanksError(error);
        return;
    }
    const std::string shared = agree(error);
    if (!shared.empty()) throw RanksError(shared);
}

void abortAll(int status) {
#if HC_WITH_MPI
    if (gStarted && gCount > 1) MPI_Abort(MPI_COMM_WORLD, status);
#else
    (void)status;
#endif
}

void sendToRoot(std::span<const std::byte> bytes) {
#if HC_WITH_MPI
    if (gCount == 1 || gRank == 0) throw Error("sendToRoot: only a rank other than 0 sends");
    const uint64_t size = bytes.size();
    check(MPI_Send(&size, 1, MPI_UINT64_T, 0, kTagSize, MPI_COMM_WORLD), "MPI_Send");
    for (size_t at = 0; at < bytes.size(); at += kChunk) {
        const size_t n = std::min(kChunk, bytes.size() - at);
        check(MPI_Send(bytes.data() + at, int(n), MPI_BYTE, 0, kTagData, MPI_COMM_WORLD), "MPI_Send");
    }
#else
    (void)bytes;
    throw Error("sendToRoot: this build has no MPI");
#endif
}

std::vector<std::byte> receiveFrom(int from) {
#if HC_WITH_MPI
    if (gRank != 0 || from <= 0 || from >= gCount) throw Error("receiveFrom: rank 0 receives from another rank");
    uint64_t size = 0;
    check(MPI_Recv(&size, 1, MPI_UINT64_T, from, kTagSize, MPI_COMM_WORLD, MPI_STATUS_IGNORE), "MPI_Recv");
    std::vector<std::byte> out(size);
    for (size_t at = 0; at < out.size(); at += kChunk) {
        const size_t n = std::min(kChunk, out.size() - at);
        check(MPI_Recv(out.data() + at, int(n), MPI_BYTE, from, kTagData, MPI_COMM_WORLD, MPI_STATUS_IGNORE),
              "MPI_Recv");
    }
    return out;
#else
    (void)from;
    throw Error("receiveFrom: this build has no MPI");
#endif
}

void receiveInto(int from, std::span<std::byte> out) {
#if HC_WITH_MPI
    if (gRank != 0 || from <= 0 || from >= gCount) throw Error("receiveInto: rank 0 receives from another rank");
    uint64_t size = 0;
    check(MPI_Recv(&size, 1, MPI_UINT64_T, from, kTagSize, MPI_COMM_WORLD, MPI_STATUS_IGNORE), "MPI_Recv");
    if (size != out.size())
        throw Error("rank " + std::to_string(from + 1) + " sent " + std::to_string(size) + " bytes where " +
                    std::to_string(out.size()) + " were agreed");
    for (size_t at = 0; at < out.size(); at += kChunk) {
        const size_t n = std::min(kChunk, out.size() - at);
        check(MPI_Recv(out.data() + at, int(n), MPI_BYTE, from, kTagData, MPI_COMM_WORLD, MPI_STATUS_IGNORE),
              "MPI_Recv");
    }
#else
    (void)from, (void)out;
    throw Error("receiveInto: this build has no MPI");
#endif
}

std::vector<std::vector<std::byte>> allGather(std::span<const std::byte> bytes) {
    if (gCount == 1) return {std::vector<std::byte>(bytes.begin(), bytes.end())};
#if HC_WITH_MPI
    if (bytes.size() > size_t(std::numeric_limits<int>::max()))
        throw Error("allGather: a table over 2 GB; send it to rank 0 instead");
    const int mine = int(bytes.size());
    std::vector<int> sizes(static_cast<size_t>(gCount)), at(static_cast<size_t>(gCount));
    check(MPI_Allgather(&mine, 1, MPI_INT, sizes.data(), 1, MPI_INT, MPI_COMM_WORLD), "MPI_Allgather");
    int64_t total = 0;
    for (int r = 0; r < gCount; ++r) {
        at[size_t(r)] = int(total);
        total += sizes[size_t(r)];
    }
    if (total > std::numeric_limits<int>::max()) throw Error("allGather: tables over 2 GB together");
    std::vector<std::byte> all(static_cast<size_t>(total));
    check(MPI_Allgatherv(bytes.data(), mine, MPI_BYTE, all.data(), sizes.data(), at.data(), MPI_BYTE, MPI_COMM_WORLD),
          "MPI_Allgatherv");
    std::vector<std::vector<std::byte>> out(static_cast<size_t>(gCount));
    for (int r = 0; r < gCount; ++r)
        out[size_t(r)].assign(all.begin() + at[size_t(r)], all.begin() + at[size_t(r)] + sizes[size_t(r)]);
    return out;
#else
    throw Error("allGather: this build has no MPI");
#endif
}

void log(const char* program, const std::string& line) {
    if (gCount == 1) return;
    std::fprintf(stderr, "%s: %s: %s\n", program, name().c_str(), line.c_str());
    std::fflush(stderr);
}

}  // namespace hc::ranks
