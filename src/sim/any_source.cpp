#include "vofusion/sim/any_source.h"

#include <filesystem>

#include "vofusion/core/errors.h"
#include "vofusion/io/rawlog.h"
#include "vofusion/io/seven_scenes_source.h"
#include "vofusion/io/tum_source.h"
#include "vofusion/sim/synthetic_source.h"

namespace fs = std::filesystem;

namespace vofusion {

namespace {
// --depth-scale is read by a TUM folder's source only: any other input saying nothing of it would be
// run with the option silently ignored.
void refuseDepthScale(const SourceOptions& opts, const std::string& path, const std::string& kind) {
  if (opts.depth_scale != 0.0)
    throw InputError(path, "--depth-scale is for a TUM folder's depth PNGs; " + kind + " carries its own depth units");
}

// A folder that cannot be searched (no execute permission) or listed (no read) says so: it was "not a
// TUM RGB-D sequence nor a 7-Scenes one", since rgb.txt then reads as missing and no frame is seen.
void refuseUnreadableFolder(const std::string& path, const std::error_code& ec) {
  if (ec && ec != std::errc::no_such_file_or_directory) throw InputError(path, "folder cannot be read (" + ec.message() + ")");
}
// Whether the folder lists its colour images in rgb.txt (a TUM folder, read by its files' names: it
// needs no listing), refused when the folder cannot be searched.
bool holdsRgbList(const std::string& path) {
  std::error_code ec;
  const fs::file_status st = fs::symlink_status(fs::path(path) / "rgb.txt", ec);
  refuseUnreadableFolder(path, ec);
  return fs::exists(st);
}
void requireListable(const std::string& path) {
  std::error_code ec;
  fs::directory_iterator(path, ec);
  refuseUnreadableFolder(path, ec);
}
}  // namespace

std::unique_ptr<FrameSource> openFrameSource(const std::string& path, const SourceOptions& opts) {
  std::error_code ec;  // a link to nowhere or to itself is no input: "no such file or folder"
  if (path.rfind("synthetic", 0) == 0 && !fs::exists(path, ec)) {
    refuseDepthScale(opts, path, "a synthetic recording");
    return std::make_unique<sim::SyntheticSource>(sim::SyntheticSource::optionsFromSpec(path, opts));
  }
  if (fs::is_directory(path, ec)) {
    if (holdsRgbList(path)) return std::make_unique<TumFolderSource>(path, opts);
    requireListable(path);
    if (SevenScenesSource::looksLike(path)) {
      refuseDepthScale(opts, path, "a 7-Scenes folder (millimetres)");
      return std::make_unique<SevenScenesSource>(path, opts);
    }
    throw InputError(path, "folder is not a TUM RGB-D sequence (no rgb.txt) nor a 7-Scenes one (no frame-XXXXXX.depth.png)");
  }
  if (!fs::exists(path, ec)) throw InputError(path, "no such file or folder");
  if (fs::path(path).extension() == ".rawlog") {
    refuseDepthScale(opts, path, "a rawlog");
    return std::make_unique<RawlogSource>(path, opts);
  }
  throw InputError(path, "unknown input type (expected a TUM folder, a .rawlog file or 'synthetic')");
}

}  // namespace vofusion
