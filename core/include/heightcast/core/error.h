// heightcast/core/error.h: the one exception type for bad input from the world.
//
// Two tiers of errors (CONTRIBUTING.md): broken invariants inside our own code are assert()s;
// bad input (files, rasters, options, camera values) throws hc::Error with a message that names
// the input and the problem. Tools catch it in main(), print it on one line and exit non-zero.
#pragma once

#include <stdexcept>
#include <string>

namespace hc {

class Error : public std::runtime_error {
public:
    explicit Error(const std::string& message) : std::runtime_error(message) {}
};

}  // namespace hc
