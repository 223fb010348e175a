#pragma once
// The run's outputs staged and moved into place together. Private to src/pipeline/.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "vofusion/core/atomic_file.h"
#include "vofusion/core/errors.h"

namespace vofusion {

// Output files written into a staging folder and moved into place together, only once all of them
// were written: a failure (disk full) leaves an earlier run's outputs intact. Each is logged with the
// time since the previous one.
class StagedOutputs {
 public:
  explicit StagedOutputs(std::function<std::string(const std::string&)> final_path)
      : final_path_(std::move(final_path)), staging_(final_path_(".staging")), last_(std::chrono::steady_clock::now()) {
    // The output folder, gone or unwritable since the run began (a full disk): named as the user knows
    // it, in one line (std::filesystem's error named the staging folder, with its own wording).
    std::error_code ec;
    std::filesystem::create_directories(staging_.tmp(), ec);
    if (ec) throw InputError(std::filesystem::path(staging_.path()).parent_path().string(), "cannot write: " + ec.message());
  }
  std::string path(const std::string& name) const { return (std::filesystem::path(staging_.tmp()) / name).string(); }
  // An error a writer threw naming its staged copy, naming the file as the user will find it (the
  // staging folder is gone by the time the error is read).
  InputError named(const InputError& e) const {
    const std::string staged = staging_.tmp() + "/";
    if (e.file().rfind(staged, 0) != 0) return e;
    return InputError(final_path_(e.file().substr(staged.size())), e.problem());
  }
  // `name` is done; staged = false: it was written in place (the rawlog, committed by its writer).
  void wrote(const std::string& name, const std::string& what, bool staged = true) {
    const auto now = std::chrono::steady_clock::now();
    const double seconds = std::chrono::duration<double>(now - last_).count();
    last_ = now;
    char line[1024];
    std::snprintf(line, sizeof line, "  wrote %s  (%s; %.1f s)\n", final_path_(name).c_str(), what.c_str(), seconds);
    log_lines_.push_back(line);
    if (staged) names_.push_back(name);
    seconds_.emplace_back(name, seconds);
  }
  // Each file written so far and the seconds since the one before it (the first: since the outputs
  // began, after the last frame), as the log lines say them.
  const std::vector<std::pair<std::string, double>>& secondsEach() const { return seconds_; }
  // Of the files a run may write (`every`), those in the folder that this run did not write: an
  // earlier run's, left as they were (nothing written is removed) but no longer this folder's results.
  std::vector<std::string> leftFromEarlier(const std::vector<std::string>& every) const {
    std::vector<std::string> left;
    for (const std::string& name : every) {
      std::error_code ec;
      const bool written = std::any_of(seconds_.begin(), seconds_.end(), [&](const auto& w) { return w.first == name; });
      if (!written && std::filesystem::exists(final_path_(name), ec))
        left.push_back(name);
    }
    return left;
  }
  // Refuses a folder where a staged file goes: called before any file moves (the files before it were
  // in place, new, beside the earlier run's rest), and by the caller before it puts a file of its own.
  void checkPlaces() const {
    for (const std::string& name : names_) refuseFolderWhereAFileGoes(final_path_(name));
  }
  void commit(std::FILE* log) {
    checkPlaces();
    for (const std::string& name : names_) {
      std::error_code ec;
      std::filesystem::rename(path(name), final_path_(name), ec);
      if (ec) throw InputError(final_path_(name), "cannot write: " + ec.message());
    }
    // Each file's bytes went to the disk with its own commit; the renames out of staging follow them.
    if (!names_.empty()) syncFolderEntries(std::filesystem::path(final_path_(names_.front())).parent_path().string());
    if (log)
      for (const std::string& l : log_lines_) std::fputs(l.c_str(), log);
  }

 private:
  std::function<std::string(const std::string&)> final_path_;
  AtomicPath staging_;
  std::chrono::steady_clock::time_point last_;
  std::vector<std::string> names_, log_lines_;
  std::vector<std::pair<std::string, double>> seconds_;  // every file written (staged or not), in order
};

}  // namespace vofusion
