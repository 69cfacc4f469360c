// apps/render/outputs.h: what hc-render writes for a frame (the PNG, EXR layers, timings JSON), on a thread of its own
// for sequences and flights, and the H.264 video made while the frames come (ffmpeg reading raw frames from a pipe).
#pragma once

#include <sys/types.h>

#include <condition_variable>
#include <deque>
#include <exception>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include "heightcast/render/renderer.h"

namespace hc::render_app {

// OUT.png -> OUT_0007.png for step 7 of a sequence (and likewise the EXR and timings files).
std::string numbered(const std::string& path, unsigned step);
// The path of a program on PATH, or "".
std::string onPath(const std::string& program);

struct Rendered {
    render::Frame frame;
    render::Timings timings;
    std::string device;  // what rendered it: "CPU, N threads" or the GL renderer and version
};

// A frame's files: the PNG always, the EXR layers and the timings JSON where named; numbered with `step`.
struct OutputPaths {
    std::string png, exr, timings;
    void write(const Rendered& r, std::optional<unsigned> step) const;
};

// An H.264 MP4 (yuv420p, padded to even sizes) encoded by ffmpeg while the frames come: each frame's RGB goes down a
// pipe as raw video (no PNG encoded and decoded again on its way), into a temporary name that finish() renames into
// place; a failure, or a pipe never finished, leaves no partial video. Throws hc::Error.
class VideoPipe {
public:
    VideoPipe(const std::string& ffmpeg, const std::string& path, double fps, int width, int height);
    ~VideoPipe();
    void put(const render::Frame& f);
    void finish();

private:
    void close(bool keep);
    std::string path_, tmp_;
    int width_, height_;
    int fd_ = -1;
    pid_t pid_ = 0;
};

// Writes each frame's outputs (and its video frame) on a thread of its own while the next frame renders, so that a
// sequence or flight costs the slower of rendering and encoding a frame, not their sum. At most kInFlight frames wait
// (their memory); the first failure is thrown by the next put() or by finish(), and nothing after it is written.
class OutputWriter {
public:
    OutputWriter(OutputPaths paths, VideoPipe* video);
    ~OutputWriter();
    void put(Rendered r, std::optional<unsigned> step);
    void finish();  // every frame written, or the first failure thrown

private:
    static constexpr size_t kInFlight = 2;
    struct Job {
        Rendered r;
        std::optional<unsigned> step;
    };
    void loop();
    void stop();
    OutputPaths paths_;
    VideoPipe* video_;
    std::mutex mutex_;
    std::condition_variable changed_;
    std::deque<Job> jobs_;
    std::exception_ptr failure_;
    bool done_ = false;
    std::thread thread_;  // last: started once the rest is ready
};

}  // namespace hc::render_app
