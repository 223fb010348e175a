#pragma once
// The live 3D window (mrpt::gui::CDisplayWindow3D): the current view (ray-cast of the model when a
// reconstruction runs, else the colour image) as an inset, the camera path and the current camera
// in 3D, and a status line: fps, tracking state, dropped frames. Redraws at most ~10 times a second.
#include <chrono>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <mrpt/gui/CDisplayWindow3D.h>
#include <mrpt/opengl/CSetOfLines.h>
#include <mrpt/opengl/CSetOfObjects.h>
#include <mrpt/poses/CPose3D.h>
#include <opencv2/core.hpp>

#include "vofusion/live/live_loop.h"

namespace vofusion {

struct LiveView {
  cv::Mat image;                            // BGR: ray-cast view, or the colour frame
  std::optional<mrpt::poses::CPose3D> pose;  // camera-to-world, when something tracks
  std::string tracking = "recording only";  // "tracking", "LOST", "fell back to odometry", ...
  // Loops closed since the last view: the two camera poses each joins (drawn as a line), and a status
  // line for the window ("loop closed: frames 12 and 240, 4.1 cm"); empty when none.
  std::vector<std::pair<mrpt::poses::CPose3D, mrpt::poses::CPose3D>> new_loops;
  std::string loop_status;
};

class LiveViewer {
 public:
  // Throws InputError("--live", ...) when no display is available (use --no-gui).
  explicit LiveViewer(const std::string& title);
  ~LiveViewer();
  // After each processed frame (the calling thread of runLive).
  void show(const LiveView& view, const LiveStats& stats);
  // Whether the next show() draws its image (at most ~10 Hz): the caller renders one only then (a ray
  // cast of the map, which also waits for the frame's fusion).
  bool wantsImage() const;
  // Status only (between frames).
  void status(const LiveStats& stats);
  // False once the user closed the window (the app then stops the run).
  bool isOpen();

 private:
  void drawText(const LiveStats& stats);
  // show()'s changes to the scene, made while it is locked.
  void updateScene(const LiveView& view, const LiveStats& stats, mrpt::opengl::COpenGLScene::Ptr& scene, bool redraw);
  mrpt::gui::CDisplayWindow3D::Ptr win_;
  mrpt::opengl::CSetOfLines::Ptr path_;
  mrpt::opengl::CSetOfLines::Ptr loops_;  // accepted loops, between the poses they join
  std::string loop_status_;
  mrpt::opengl::CSetOfObjects::Ptr camera_;
  std::optional<mrpt::poses::CPose3D> last_pose_;
  std::string tracking_ = "waiting for frames";
  std::chrono::steady_clock::time_point last_draw_{};
};

}  // namespace vofusion
