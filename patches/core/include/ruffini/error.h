#pragma once
// Errors that come from outside (files, command lines, recordings). Broken invariants abort instead.
#include <stdexcept>
#include <string>

namespace ruffini {

// A configuration or input error. The message already names the place (file:line:col or line N),
// the key and what was expected; callers print it as is.
class InputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

}  // namespace ruffini
