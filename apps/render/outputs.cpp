// apps/render/outputs.cpp: hc-render's outputs (outputs.h says what each part does).
#include "render/outputs.h"

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <span>
#include <vector>

#include <fmt/format.h>

#include "heightcast/core/atomic_file.h"
#include "heightcast/core/error.h"
#include "heightcast/render/image_io.h"

namespace hc::render_app {

std::string numbered(const std::string& path, unsigned step) {
    std::filesystem::path p(path);
    char tail[32];
    std::snprintf(tail, sizeof tail, "_%04u", step);
    return (p.parent_path() / (p.stem().string() + tail + p.extension().string())).string();
}

std::string onPath(const std::string& program) {
    const char* path = std::getenv("PATH");
    std::string dirs = path ? path : "/usr/bin:/bin";
    size_t start = 0;
    for (;;) {
        const size_t colon = dirs.find(':', start);
        const std::string dir = dirs.substr(start, colon == std::string::npos ? std::string::npos : colon - start);
        const std::string candidate = (dir.empty() ? std::string(".") : dir) + "/" + program;
        if (::access(candidate.c_str(), X_OK) == 0) return candidate;
        if (colon == std::string::npos) return "";
        start = colon + 1;
    }
}

void OutputPaths::write(const Rendered& r, std::optional<unsigned> step) const {
    auto name = [&](const std::string& path) { return step ? numbered(path, *step) : path; };
    render::writePng(r.frame, name(png));
    if (!exr.empty()) render::writeFrameExr(r.frame, name(exr));
    if (!timings.empty()) {
        AtomicFileWriter tw(name(timings));
        const std::string j = r.timings.toJson();
        tw.write(std::as_bytes(std::span(j)));
        tw.commit();
    }
}

// ---------------------------------------------------------------------------------------------------- the video

VideoPipe::VideoPipe(const std::string& ffmpeg, const std::string& path, double fps, int width, int height)
    : path_(path), tmp_(path + ".partial"), width_(width), height_(height) {
    std::signal(SIGPIPE, SIG_IGN);  // ffmpeg gone: write() fails with EPIPE, said below, instead of killing us
    int fds[2];
    if (::pipe2(fds, O_CLOEXEC) != 0) throw Error(std::string("--video: pipe: ") + std::strerror(errno));
    std::vector<std::string> args{ffmpeg,
                                  "-hide_banner",
                                  "-loglevel",
                                  "error",
                                  "-y",
                                  "-f",
                                  "rawvideo",
                                  "-pix_fmt",
                                  "rgb24",
                                  "-video_size",
                                  fmt::format("{}x{}", width, height),
                                  "-framerate",
                                  fmt::format("{:g}", fps),
                                  "-i",
                                  "-",
                                  "-vf",
                                  "pad=ceil(iw/2)*2:ceil(ih/2)*2",
                                  "-c:v",
                                  "libx264",
                                  "-pix_fmt",
                                  "yuv420p",
                                  "-f",
                                  "mp4",
                                  tmp_};
    std::vector<char*> argv;
    for (auto& s : args) argv.push_back(s.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_adddup2(&actions, fds[0], STDIN_FILENO);  // dup2 clears O_CLOEXEC on stdin
    const int spawned = posix_spawn(&pid_, ffmpeg.c_str(), &actions, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&actions);
    ::close(fds[0]);
    if (spawned != 0) {
        ::close(fds[1]);
        pid_ = 0;
        throw Error(ffmpeg + ": cannot be started");
    }
    fd_ = fds[1];
}

VideoPipe::~VideoPipe() {
    if (pid_) close(false);
}

void VideoPipe::put(const render::Frame& f) {
    if (f.width != width_ || f.height != height_ || f.rgb.size() != size_t(width_) * size_t(height_) * 3)
        throw Error(path_ + ": a frame of " + std::to_string(f.width) + "x" + std::to_string(f.height) +
                    " in a video of " + std::to_string(width_) + "x" + std::to_string(height_));
    const auto* p = reinterpret_cast<const char*>(f.rgb.data());
    size_t left = f.rgb.size();
    while (left) {
        const ssize_t n = ::write(fd_, p, left);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) {
            const std::string why = std::strerror(errno);
            close(false);
            throw Error(path_ + ": ffmpeg stopped reading the frames (" + why + "); the images written so far stay");
        }
        p += n, left -= size_t(n);
    }
}

void VideoPipe::finish() { close(true); }

// Ends the input, waits for ffmpeg, and renames its output into place (keep) or removes it.
void VideoPipe::close(bool keep) {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
    int status = 0;
    while (::waitpid(pid_, &status, 0) < 0 && errno == EINTR) {
    }
    pid_ = 0;
    std::error_code ec;
    if (!keep) {
        std::filesystem::remove(tmp_, ec);
        return;
    }
    if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
        std::filesystem::remove(tmp_, ec);
        throw Error(path_ + ": ffmpeg failed (exit status " +
                    std::to_string(WIFEXITED(status) ? WEXITSTATUS(status) : -1) + "); the images written so far stay");
    }
    std::filesystem::rename(tmp_, path_, ec);
    if (ec) {
        std::filesystem::remove(tmp_, ec);
        throw Error(path_ + ": cannot be written: " + ec.message());
    }
}

// ---------------------------------------------------------------------------------------------- the writer

OutputWriter::OutputWriter(OutputPaths paths, VideoPipe* video)
    : paths_(std::move(paths)), video_(video), thread_([this] { loop(); }) {}

OutputWriter::~OutputWriter() { stop(); }

void OutputWriter::put(Rendered r, std::optional<unsigned> step) {
    std::unique_lock lock(mutex_);
    changed_.wait(lock, [&] { return jobs_.size() < kInFlight || failure_; });
    if (failure_) std::rethrow_exception(failure_);
    jobs_.push_back({std::move(r), step});
    changed_.notify_all();
}

void OutputWriter::finish() {
    stop();
    if (failure_) std::rethrow_exception(failure_);
}

void OutputWriter::loop() {
    for (;;) {
        std::unique_lock lock(mutex_);
        changed_.wait(lock, [&] { return !jobs_.empty() || done_; });
        if (jobs_.empty()) return;
        Job& job = jobs_.front();
        const bool failed = bool(failure_);
        lock.unlock();
        std::exception_ptr error;
        try {
            if (!failed) {
                paths_.write(job.r, job.step);
                if (video_) video_->put(job.r.frame);
            }
        } catch (...) {
            error = std::current_exception();
        }
        lock.lock();
        if (error) failure_ = error;
        jobs_.pop_front();
        changed_.notify_all();
    }
}

void OutputWriter::stop() {
    {
        std::lock_guard lock(mutex_);
        done_ = true;
    }
    changed_.notify_all();
    if (thread_.joinable()) thread_.join();
}

}  // namespace hc::render_app
