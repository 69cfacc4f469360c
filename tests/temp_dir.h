// tests/temp_dir.h: the tests' temporary files. TempDirTest is a fixture with a fresh directory of its own, made before
// each test and removed after it (named by the test program's prefix, the process and the test, so that ctest -j runs
// never share one). tempPath() names a file of its own for a helper that outlives a test (a static cache, removing its
// file when the program ends).
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <utility>
#include <vector>

namespace hc::test {

// PREFIX<pid>_NAME under the system's temporary directory: this process's own.
inline std::filesystem::path tempPath(const std::string& prefix, const std::string& name) {
    return std::filesystem::temp_directory_path() / (prefix + std::to_string(::getpid()) + "_" + name);
}

class TempDirTest : public ::testing::Test {
protected:
    explicit TempDirTest(std::string prefix) : prefix_(std::move(prefix)) {}
    void SetUp() override {
        // A parameterised test's name is NAME/INDEX: one directory, not one inside another.
        std::string test = ::testing::UnitTest::GetInstance()->current_test_info()->name();
        std::replace(test.begin(), test.end(), '/', '_');
        dir_ = tempPath(prefix_, test);
        std::filesystem::remove_all(dir_);  // left by a run that crashed
        std::filesystem::create_directories(dir_);
    }
    void TearDown() override { std::filesystem::remove_all(dir_); }
    std::string path(const std::string& name) const { return (dir_ / name).string(); }
    std::filesystem::path dir_;

private:
    std::string prefix_;
};

// A file's bytes, and the first n of `bytes` written as a file (the format tests' truncations and flipped bytes).
inline std::vector<char> readBytes(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), {}};
}
inline void writeBytes(const std::string& path, const std::vector<char>& bytes, size_t n) {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), static_cast<std::streamsize>(n));
}

// TempDirTest for TEST_P: GetParam() as in ::testing::TestWithParam<P>.
template <typename P>
class TempDirTestWithParam : public TempDirTest, public ::testing::WithParamInterface<P> {
protected:
    using TempDirTest::TempDirTest;
};

}  // namespace hc::test
