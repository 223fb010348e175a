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

}  // namespace vofusion
