// rgbd-eval <groundtruth.txt> <estimate.txt> [--delta 1.0] [--max-dt 0.02] [--json] [--plot out.png]
// The TUM benchmark's ATE and RPE, printed as the rows of the paper's Table 1.
#include <algorithm>
#include <cctype>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <string>

#include <nlohmann/json.hpp>

#include "vofusion/core/cli.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/progress.h"
#include "vofusion/core/trajectory.h"
#include "vofusion/eval/trajectory_eval.h"

using namespace vofusion;

namespace {
const char* kUsage =
    "usage: rgbd-eval <groundtruth.txt> <estimate.txt> [--delta S] [--max-dt S] [--json] [--plot out.png]\n"
    "  TUM-format trajectories (timestamp tx ty tz qx qy qz qw, camera-to-world).\n"
    "  --delta S    RPE pose-pair spacing in seconds (default 1.0)\n"
    "  --max-dt S   timestamp association tolerance (default 0.02)\n"
    "  --json       machine-readable output\n"
    "  --plot P     PNG: top view with error vectors (left), translational error over time (right)\n";

std::string statsJson(const ErrorStats& s) {
  char b[400];
  std::snprintf(b, sizeof b,
                "{\"count\": %zu, \"rmse\": %.9g, \"mean\": %.9g, \"median\": %.9g, \"std\": %.9g, \"min\": %.9g, "
                "\"max\": %.9g, \"p95\": %.9g}",
                s.count, s.rmse, s.mean, s.median, s.std, s.min, s.max, s.p95);
  return b;
}

// A path or message as a JSON string, quoted and escaped (a folder named "seq\1" made the output no JSON);
// bytes that are no UTF-8 become U+FFFD.
std::string jsonString(const std::string& text) {
  return nlohmann::json(text).dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

int body(int argc, char** argv) {
  const CommandLine cl(argc, argv, {"--delta", "--max-dt", "--plot"}, {"--json", "--help"});
  if (cl.flag("--help")) {
    std::cout << kUsage;
    return 0;
  }
  const double delta = cl.number("--delta", 1.0, 0.0);
  const double max_dt = cl.number("--max-dt", 0.02, 0.0);
  const bool json = cl.flag("--json");
  const std::string plot = cl.value("--plot", "");
  // The plot is a PNG's bytes: under another name (x.jpg) it passed for what it is not.
  std::string ext = std::filesystem::path(plot).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  if (!plot.empty() && ext != ".png") throw InputError("--plot", "writes a PNG: give a .png name, got '" + plot + "'");
  const auto& pos = cl.positional();
  if (pos.size() != 2) throw InputError("usage", "expected <groundtruth.txt> <estimate.txt> (see --help)");

  const Trajectory gt = readTumTrajectory(pos[0]);
  const Trajectory est = readTumTrajectory(pos[1], StampOrder::AsWritten);  // a run's frames in their order
  if (gt.empty()) throw InputError(pos[0], "contains no poses");
  if (est.empty()) throw InputError(pos[1], "contains no poses");
  if (const std::size_t repeated = est.size() - onePosePerStamp(est).size())
    printWarning(pos[1] + ": " + std::to_string(repeated) + (repeated == 1 ? " pose repeats" : " poses repeat") +
                 " an earlier pose's stamp: the last pose of each stamp is evaluated, as TUM's scripts read the file");
  const AteResult ate = computeAte(gt, est, max_dt);
  if (!ate.success) throw InputError(gt.size() < 3 ? pos[0] : pos[1], ate.message);  // the one too short, else the estimate
  const RpeResult rpe = computeRpe(gt, est, delta, max_dt);

  if (json) {
    std::printf("{\"groundtruth\": %s, \"estimate\": %s,\n \"ate_m\": %s,\n", jsonString(pos[0]).c_str(),
                jsonString(pos[1]).c_str(), statsJson(ate.trans).c_str());
    if (rpe.success)
      std::printf(" \"rpe\": {\"delta_s\": %.9g, \"trans_m\": %s,\n         \"rot_deg\": %s}}\n", delta,
                  statsJson(rpe.trans).c_str(), statsJson(rpe.rot_deg).c_str());
    else
      std::printf(" \"rpe\": null, \"rpe_error\": %s}\n", jsonString(rpe.message).c_str());
  } else {
    std::printf("%zu poses associated (ATE), %zu pose pairs %.3g s apart (RPE)\n", ate.trans.count,
                rpe.trans.count, delta);
    std::printf("%-8s %12s %16s %15s\n", "", "ATE [m]", "RPE trans [m]", "RPE rot [deg]");
    auto row = [&](const char* name, double a, double t, double r) {
      if (rpe.success) std::printf("%-8s %12.6f %16.6f %15.6f\n", name, a, t, r);
      else std::printf("%-8s %12.6f %16s %15s\n", name, a, "-", "-");
    };
    row("Std", ate.trans.std, rpe.trans.std, rpe.rot_deg.std);
    row("Median", ate.trans.median, rpe.trans.median, rpe.rot_deg.median);
    row("RMS", ate.trans.rmse, rpe.trans.rmse, rpe.rot_deg.rmse);
    row("Mean", ate.trans.mean, rpe.trans.mean, rpe.rot_deg.mean);
    row("P95", ate.trans.p95, rpe.trans.p95, rpe.rot_deg.p95);
    row("Max", ate.trans.max, rpe.trans.max, rpe.rot_deg.max);
    if (!rpe.success) std::printf("RPE: %s\n", rpe.message.c_str());
  }
  if (!plot.empty()) plotAteReport(plot, ate, pos[1]);
  return 0;
}

}  // namespace

int main(int argc, char** argv) { return runApp("rgbd-eval", body, argc, argv); }
