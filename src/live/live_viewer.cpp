#include "vofusion/live/live_viewer.h"

#include <cstdio>
#include <cstdlib>

#include <mrpt/img/CImage.h>
#include <mrpt/opengl/CGridPlaneXY.h>
#include <mrpt/opengl/COpenGLScene.h>
#include <mrpt/opengl/stock_objects.h>

#include "vofusion/core/errors.h"

namespace vofusion {

namespace {
constexpr std::chrono::milliseconds kRedrawEvery{100};  // the image and repaint at most ~10 Hz

// The window's scene, locked for as long as this lives: an exception while drawing (out of memory)
// leaves it unlocked, or the GUI thread's next paint would wait forever.
struct SceneLock {
  mrpt::gui::CDisplayWindow3D& win;
  mrpt::opengl::COpenGLScene::Ptr& scene;
  explicit SceneLock(mrpt::gui::CDisplayWindow3D& w) : win(w), scene(w.get3DSceneAndLock()) {}
  ~SceneLock() { win.unlockAccess3DScene(); }
  SceneLock(const SceneLock&) = delete;
  SceneLock& operator=(const SceneLock&) = delete;
};
}  // namespace

LiveViewer::LiveViewer(const std::string& title) {
  const char* display = std::getenv("DISPLAY");
  const char* wayland = std::getenv("WAYLAND_DISPLAY");
  if ((!display || !*display) && (!wayland || !*wayland))
    throw InputError("--live", "no display for the live window (DISPLAY is not set): add --no-gui");
  win_ = mrpt::gui::CDisplayWindow3D::Create(title, 1024, 768);
  // A display that cannot be opened (DISPLAY names no X server): MRPT only prints so and gives no
  // window, and the first frame took that for the user closing it (a run "interrupted" after one frame).
  if (!win_->isOpen())
    throw InputError("--live", std::string("cannot open the live window on the display (") +
                                   (display && *display ? std::string("DISPLAY=") + display : "WAYLAND_DISPLAY=" + std::string(wayland)) +
                                   "): add --no-gui");
  path_ = mrpt::opengl::CSetOfLines::Create();
  path_->setColor(0.9f, 0.2f, 0.2f);
  path_->setLineWidth(2.0f);
  camera_ = mrpt::opengl::stock_objects::CornerXYZSimple(0.15f, 2.0f);
  loops_ = mrpt::opengl::CSetOfLines::Create();
  loops_->setColor(1.0f, 0.85f, 0.1f);
  loops_->setLineWidth(4.0f);
  {
    const SceneLock lock(*win_);
    auto& scene = lock.scene;
    scene->insert(mrpt::opengl::CGridPlaneXY::Create(-3, 3, -3, 3, 0, 0.5f));
    scene->insert(path_);
    scene->insert(loops_);
    scene->insert(camera_);
    // Inset at the top left: the current view.
    auto inset = scene->createViewport("view");
    inset->setViewportPosition(0.0, 0.6, 0.4, 0.4);
  }
  win_->setCameraZoom(2.5f);
  win_->repaint();
}

LiveViewer::~LiveViewer() = default;

bool LiveViewer::isOpen() { return win_ && win_->isOpen(); }

void LiveViewer::drawText(const LiveStats& s) {
  char line[256];
  std::snprintf(line, sizeof line, "%zu frames  %.1f fps processed  %.1f fps sensor  dropped %zu  |  %s",
                s.processed, s.processedFps(), s.playedFps(), s.dropped, tracking_.c_str());
  mrpt::opengl::TFontParams font;
  font.color = mrpt::img::TColorf(1, 1, 1);
  win_->addTextMessage(5, 5, line, 0, font);
  if (!loop_status_.empty()) {
    font.color = mrpt::img::TColorf(1, 0.85f, 0.1f);
    win_->addTextMessage(5, 25, loop_status_, 1, font);
  }
}

void LiveViewer::status(const LiveStats& stats) {
  if (!isOpen()) return;
  const auto now = std::chrono::steady_clock::now();
  if (now - last_draw_ < std::chrono::milliseconds(500)) return;
  last_draw_ = now;
  {
    const SceneLock lock(*win_);
    drawText(stats);
  }
  win_->repaint();
}

bool LiveViewer::wantsImage() const { return std::chrono::steady_clock::now() - last_draw_ >= kRedrawEvery; }

void LiveViewer::show(const LiveView& view, const LiveStats& stats) {
  if (!isOpen()) return;
  tracking_ = view.tracking;
  if (!view.loop_status.empty()) loop_status_ = view.loop_status;
  // The path grows every frame; the heavy part (image upload, repaint) at most ~10 Hz.
  const auto now = std::chrono::steady_clock::now();
  const bool redraw = now - last_draw_ >= kRedrawEvery;
  {
    const SceneLock lock(*win_);
    updateScene(view, stats, lock.scene, redraw);
  }
  // Keep the camera in sight: the path lives wherever the map's world frame puts it.
  if (view.pose) win_->setCameraPointingToPoint(view.pose->x(), view.pose->y(), view.pose->z());
  if (redraw) win_->repaint();
}

void LiveViewer::updateScene(const LiveView& view, const LiveStats& stats, mrpt::opengl::COpenGLScene::Ptr& scene,
                             bool redraw) {
  if (view.pose) {
    if (last_pose_)
      path_->appendLine(last_pose_->x(), last_pose_->y(), last_pose_->z(), view.pose->x(), view.pose->y(), view.pose->z());
    last_pose_ = view.pose;
    camera_->setPose(*view.pose);
  }
  for (const auto& [a, b] : view.new_loops) loops_->appendLine(a.x(), a.y(), a.z(), b.x(), b.y(), b.z());
  if (redraw) {
    last_draw_ = std::chrono::steady_clock::now();
    if (!view.image.empty()) scene->getViewport("view")->setImageView(mrpt::img::CImage(view.image, mrpt::img::DEEP_COPY));
    drawText(stats);
  }
}

}  // namespace vofusion
