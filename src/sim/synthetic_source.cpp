#include "vofusion/sim/synthetic_source.h"

#include "vofusion/core/errors.h"

namespace vofusion::sim {

SimOptions SyntheticSource::optionsFromSpec(const std::string& spec, const SourceOptions& opts) {
  SimOptions s;
  if (spec.rfind("synthetic", 0) != 0) throw InputError(spec, "not a synthetic source");
  const std::string rest = spec.substr(9);
  if (!rest.empty()) {
    if (rest[0] != ':' || rest.size() == 1) throw InputError(spec, "expected 'synthetic' or 'synthetic:<scene>[:<trajectory>]'");
    s.scene = rest.substr(1);
    if (const auto colon = s.scene.find(':'); colon != std::string::npos) {
      s.trajectory = s.scene.substr(colon + 1);
      s.scene = s.scene.substr(0, colon);
      if (s.trajectory != "smooth" && s.trajectory != "shake")
        throw InputError(spec, "unknown synthetic trajectory '" + s.trajectory + "' (expected smooth or shake)");
    }
  }
  if (s.scene != "room" && s.scene != "corridor" && s.scene != "bare_wall" && s.scene != "loop" &&
      s.scene != "lookalike" && s.scene != "longwalk")
    throw InputError(spec, "unknown synthetic scene '" + s.scene +
                               "' (expected room, corridor, bare_wall, loop, lookalike or longwalk)");
  if (opts.max_frames > 0) s.frames = opts.max_frames;
  if (opts.intrinsics) {
    const CameraIntrinsics c = CameraIntrinsics::parse(*opts.intrinsics).forImage(s.camera.width, s.camera.height, "--intrinsics");
    s.camera.fx = c.fx; s.camera.fy = c.fy; s.camera.cx = c.cx; s.camera.cy = c.cy;
    s.camera.validate("--intrinsics");
  }
  return s;
}

}  // namespace vofusion::sim
