// apps/view/backends.cpp: hc-view's CPU and GL backends (see backends.h).
#include "view/backends.h"

#include <algorithm>
#include <condition_variable>
#include <mutex>
#include <optional>
#include <thread>

#include "heightcast/core/error.h"
#include "heightcast/core/parallel.h"
#include "heightcast/render/gl/gl_renderer.h"

namespace hc::view {
namespace {

using render::Camera;
using render::Frame;
using render::RenderOptions;
using render::Timings;

// Tints each pixel by the cascade that gave its hit (the Frame's cascade index): near red, then green,
// blue, yellow.
void tintCascades(Frame& f) {
    static const float kTint[4][3] = {
        {1.0f, 0.35f, 0.3f}, {0.35f, 1.0f, 0.4f}, {0.35f, 0.55f, 1.0f}, {1.0f, 0.9f, 0.3f}};
    const size_t n = size_t(f.width) * size_t(f.height);
    for (size_t i = 0; i < n && i < f.cascade.size(); ++i) {
        const int c = int(f.cascade[i]);
        if (c < 0 || c > 3) continue;
        for (int k = 0; k < 3; ++k) {
            const float v = f.rgb[i * 3 + k] * (0.45f + 0.55f * kTint[c][k]);
            f.rgb[i * 3 + k] = uint8_t(std::min(255.0f, v));
        }
    }
}

// A read-back frame into `texture`: what `shown` needs besides the camera and the timings.
void showFrame(const Frame& f, GLuint texture, Shown& shown) {
    uploadRgb(texture, f.width, f.height, f.rgb.data());
    shown.texture = texture;
    shown.flipY = true;
    shown.width = f.width, shown.height = f.height;
    const size_t centre = size_t(f.height / 2) * size_t(f.width) + size_t(f.width / 2);
    shown.centreDistanceM = centre < f.distanceM.size() ? f.distanceM[centre] : INFINITY;
}

class CpuBackend final : public ViewBackend {
public:
    CpuBackend(const render::Scene& scene, unsigned threads)
        : scene_(scene), threads_(threads), texture_(makeTexture()), worker_([this] { loop(); }) {}
    ~CpuBackend() override {
        {
            std::lock_guard<std::mutex> l(m_);
            stop_ = true;
        }
        cv_.notify_all();
        worker_.join();
    }
    bool busy() const override {
        std::lock_guard<std::mutex> l(m_);
        return job_.has_value() || running_;
    }
    void submit(const Camera& c, const RenderOptions& o, bool full, bool cascadeTint) override {
        {
            std::lock_guard<std::mutex> l(m_);
            job_ = Job{c, o, full, cascadeTint};
        }
        cv_.notify_all();
    }
    bool collect(Shown& shown) override {
        std::unique_lock<std::mutex> l(m_);
        if (!error_.empty()) throw Error(error_);
        if (!result_) return false;
        Result r = std::move(*result_);
        result_.reset();
        l.unlock();
        showFrame(r.frame, texture_, shown);
        shown.camera = r.job.camera;
        shown.full = r.job.full;
        shown.timings = r.timings;
        return true;
    }
    void wait() override {
        std::unique_lock<std::mutex> l(m_);
        done_.wait(l, [&] { return (!job_ && !running_) || !error_.empty(); });
    }
    std::string name() const override { return "CPU"; }
    std::string device() const override { return "CPU, " + std::to_string(resolveThreads(threads_)) + " threads"; }

private:
    struct Job {
        Camera camera;
        RenderOptions options;
        bool full, tint;
    };
    struct Result {
        Job job;
        Frame frame;
        Timings timings;
    };
    void loop() {
        std::unique_lock<std::mutex> l(m_);
        for (;;) {
            cv_.wait(l, [&] { return stop_ || job_.has_value(); });
            if (stop_) return;
            Job job = *job_;
            job_.reset();
            running_ = true;
            l.unlock();
            Result r{job, {}, {}};
            std::string error;
            try {
                r.frame = render::renderFrame(scene_, job.camera, job.options, r.timings, &cascades_);
                if (job.tint) tintCascades(r.frame);
            } catch (const std::exception& e) {
                error = e.what();
            }
            l.lock();
            running_ = false;
            if (!error.empty())
                error_ = error;
            else
                result_ = std::move(r);
            done_.notify_all();
        }
    }
    const render::Scene& scene_;
    render::CascadeCache cascades_;  // the worker's last textures: a moving camera evaluates only new texels
    unsigned threads_;
    GLuint texture_;
    mutable std::mutex m_;
    std::condition_variable cv_, done_;
    std::optional<Job> job_;
    std::optional<Result> result_;
    std::string error_;
    bool running_ = false, stop_ = false;
    std::thread worker_;
};

// The image stays on the GPU (renderToTexture) and is drawn from there. Cascade colouring needs the per-pixel
// cascade index, which only the read-back Frame (render()) carries: with it on, frames take that path and are
// tinted and uploaded like CPU frames. Renders synchronously in submit(): never busy.
class GlBackend final : public ViewBackend {
public:
    explicit GlBackend(std::unique_ptr<render::GlRenderer> r) : r_(std::move(r)), tintTexture_(makeTexture()) {}
    bool busy() const override { return false; }
    void submit(const Camera& c, const RenderOptions& o, bool full, bool cascadeTint) override {
        Shown s;
        s.camera = c, s.full = full, s.width = c.width, s.height = c.height;
        if (cascadeTint) {
            Frame f = r_->render(c, o, s.timings);
            tintCascades(f);
            showFrame(f, tintTexture_, s);
        } else {
            s.texture = r_->renderToTexture(c, o, s.timings);
            s.flipY = false;  // GL's convention: row 0 at the bottom
            glMemoryBarrier(GL_TEXTURE_FETCH_BARRIER_BIT);
            glBindTexture(GL_TEXTURE_2D, s.texture);
            glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
            glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
        }
        next_ = s;
    }
    bool collect(Shown& shown) override {
        if (!next_) return false;
        shown = *next_;
        next_.reset();
        return true;
    }
    void wait() override {}
    std::string name() const override { return "GL"; }
    std::string device() const override { return r_->deviceName(); }
    bool setScene(const render::Scene& scene) override {
        r_->setScene(scene);
        return true;
    }

private:
    std::unique_ptr<render::GlRenderer> r_;
    GLuint tintTexture_;
    std::optional<Shown> next_;
};

}  // namespace

std::unique_ptr<ViewBackend> makeCpuBackend(const render::Scene& scene, unsigned threads) {
    return std::make_unique<CpuBackend>(scene, threads);
}

std::unique_ptr<ViewBackend> makeGlBackend(const render::Scene& scene) {
    return std::make_unique<GlBackend>(render::GlRenderer::inCurrentContext(scene));
}

}  // namespace hc::view
