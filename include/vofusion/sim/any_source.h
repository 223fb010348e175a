#pragma once
// Opens any input by name: a TUM RGB-D folder, a 7-Scenes folder, an MRPT rawlog, or a synthetic
// scene. It lives here, above io, because it is the one place that knows every kind, the synthetic
// one included.
#include <memory>
#include <string>

#include "vofusion/io/frame_source.h"

namespace vofusion {

// Detects the kind of input: a directory with rgb.txt/depth.txt (TUM), a 7-Scenes folder, a *.rawlog
// file, or the word "synthetic[:scene][:shake]". Throws InputError naming the path when it is none of
// these.
std::unique_ptr<FrameSource> openFrameSource(const std::string& path, const SourceOptions& opts = {});

}  // namespace vofusion
