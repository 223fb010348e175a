#pragma once
// One exception type for bad input: its what() is the whole one-line message an app prints,
// always "<file>: <problem>", so users see which file to fix.
#include <stdexcept>
#include <string>

namespace vofusion {

class InputError : public std::runtime_error {
 public:
  InputError(const std::string& file, const std::string& problem)
      : std::runtime_error(file + ": " + problem), file_(file), problem_(problem) {}
  const std::string& file() const { return file_; }
  const std::string& problem() const { return problem_; }

 private:
  std::string file_, problem_;
};

// An exception's message on one line: MRPT's span several (message, location, call stack), and only
// the message is kept.
std::string oneLineMessage(const std::exception& e);

}  // namespace vofusion
