// [mesh] parameters and the JSON form of the cleaning report (kept apart from the CGAL unit, which
// compiles slowly).
#include <cmath>
#include <cstdio>
#include <sstream>

#include <mrpt/config/CConfigFileBase.h>

#include "vofusion/core/config.h"
#include "vofusion/core/errors.h"

#include "vofusion/mesh/mesh_clean.h"

namespace vofusion {

namespace {
// Every key of the section, once: loading and saving both walk this list.
std::vector<ConfigKey> meshCleanKeys(MeshCleanParams& p) {
  return {
      {"repair", &p.repair, "merge duplicates, drop degenerate/duplicate faces, orient, make manifold, stitch"},
      {"weld_distance", &p.weld_distance, "m, also merge vertices closer than this (0: exact duplicates only)", 0.0, 1.0},
      {"min_component_faces", &p.min_component_faces, "faces, smaller connected components are removed (0: off)", 0.0, 1000000000.0},
      {"min_component_area", &p.min_component_area, "m^2, smaller connected components are removed (0: off)", 0.0, 1000000.0},
      {"max_hole_perimeter", &p.max_hole_perimeter, "m, longer hole borders stay open (0: fill no holes)", 0.0, 100.0},
      {"max_hole_edges", &p.max_hole_edges, "edges, hole borders with more edges stay open", 0.0, 1000000.0},
      {"hole_fairing", &p.hole_fairing, "fair (smooth) hole patches; false: flat refined patch"},
      {"max_simplify_error", &p.max_simplify_error, "m, quadric simplification up to this error, an RMS distance to the merged faces (0: off)", 0.0, 1.0},
      {"target_faces", &p.target_faces, "faces of the whole mesh, edge-collapse simplification target, shared among regions by their faces (0: off)", 0.0, 1000000000.0},
      {"target_edge_length", &p.target_edge_length, "m, simplify until no shorter edge is left (0: off; only with max_simplify_error = 0)", 0.0, 10.0},
      {"smooth_iterations", &p.smooth_iterations, "iterations of curvature-flow shape smoothing (0: off)", 0.0, 1000.0},
      {"smooth_time", &p.smooth_time, "time step of the curvature flow per iteration", 0.0, 1.0},
      {"relax_iterations", &p.relax_iterations, "iterations of tangential relaxation (0: off)", 0.0, 1000.0},
      {"orient_closed_outward", &p.orient_closed_outward, "orient closed results with normals outward, for closed objects from elsewhere (a TSDF mesh faces the space its cameras saw: a closed room turned inside out)"},
      {"recompute_normals", &p.recompute_normals, "write fresh vertex normals (false: none written)"},
      {"region_bricks", &p.region_bricks, "bricks per region edge, vofusion meshes and simplifies region by region (0: whole world; so too with [output] clean_mesh off or save_full_mesh on)", 0.0, 4096.0},
  };
}
}  // namespace

void MeshCleanParams::loadFromConfigFile(const mrpt::config::CConfigFileBase& cfg, const std::string& s) {
  loadKeys(cfg, s, meshCleanKeys(*this));
  // The error-bounded order is not by length: a length target would stop it at a random point.
  if (max_simplify_error > 0 && target_edge_length > 0)
    throw InputError("[" + s + "] target_edge_length", "works only with max_simplify_error = 0 (shortest edges first)");
}

void MeshCleanParams::saveToConfigFile(mrpt::config::CConfigFileBase& cfg, const std::string& s) const {
  saveKeys(cfg, s, meshCleanKeys(const_cast<MeshCleanParams&>(*this)));
}

static std::string jsonString(const std::string& s) {
  std::string o = "\"";
  for (char ch : s) {
    if (ch == '"' || ch == '\\') { o += '\\'; o += ch; }
    else if (static_cast<unsigned char>(ch) < 0x20) { char b[8]; std::snprintf(b, sizeof b, "\\u%04x", ch); o += b; }
    else o += ch;
  }
  return o + "\"";
}

static std::string num(double v) {
  if (!std::isfinite(v)) return "null";  // JSON has no nan / inf
  char b[32];
  std::snprintf(b, sizeof b, "%.6g", v);
  return b;
}

std::string MeshCleanReport::toJson() const {
  std::ostringstream o;
  o << "{\"success\": " << (success ? "true" : "false");
  if (!success) o << ", \"failure\": " << jsonString(failure);
  if (!warning.empty()) o << ", \"warning\": " << jsonString(warning);
  o << ", \"steps\": [";
  for (std::size_t i = 0; i < steps.size(); ++i) {
    const auto& s = steps[i];
    o << (i ? ", " : "") << "{\"name\": " << jsonString(s.name) << ", \"vertices_before\": " << s.vertices_before
      << ", \"faces_before\": " << s.faces_before << ", \"vertices_after\": " << s.vertices_after
      << ", \"faces_after\": " << s.faces_after << ", \"seconds\": " << num(s.seconds) << "}";
  }
  o << "], \"duplicate_vertices_merged\": " << duplicate_vertices_merged
    << ", \"degenerate_faces_removed\": " << degenerate_faces_removed
    << ", \"duplicate_faces_removed\": " << duplicate_faces_removed
    << ", \"border_edges_stitched\": " << border_edges_stitched
    << ", \"non_manifold_vertices_split\": " << non_manifold_vertices_split
    << ", \"components_removed\": " << components_removed << ", \"components_kept\": " << components_kept
    << ", \"holes_filled\": " << holes_filled << ", \"holes_left\": " << holes_left
    << ", \"holes_not_faired\": " << holes_not_faired
    << ", \"border_cycles_after\": " << border_cycles_after << ", \"closed\": " << (closed ? "true" : "false")
    << ", \"manifold\": " << (manifold ? "true" : "false") << ", \"area\": " << num(area);
  if (simplification.ran) {
    const auto& s = simplification;
    o << ", \"simplification\": {\"faces_before\": " << s.faces_before << ", \"faces_after\": " << s.faces_after
      << ", \"distance_samples\": " << s.distance.samples << ", \"mean_distance_m\": " << num(s.distance.mean)
      << ", \"max_distance_m\": " << num(s.distance.max) << ", \"seconds\": " << num(s.seconds) << "}";
  }
  o << "}";
  return o.str();
}

}  // namespace vofusion
