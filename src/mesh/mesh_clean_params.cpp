// [mesh] parameters and the JSON form of the cleaning report (kept apart from the CGAL unit, which
// compiles slowly).
#include <cstdio>
#include <sstream>

#include <mrpt/config/CConfigFileBase.h>

#include "vofusion/mesh/mesh_clean.h"

namespace vofusion {

void MeshCleanParams::loadFromConfigFile(const mrpt::config::CConfigFileBase& c, const std::string& s) {
  repair = c.read_bool(s, "repair", repair);
  weld_distance = c.read_double(s, "weld_distance", weld_distance);
  min_component_faces = c.read_int(s, "min_component_faces", min_component_faces);
  min_component_area = c.read_double(s, "min_component_area", min_component_area);
  max_hole_perimeter = c.read_double(s, "max_hole_perimeter", max_hole_perimeter);
  max_hole_edges = c.read_int(s, "max_hole_edges", max_hole_edges);
  hole_fairing = c.read_bool(s, "hole_fairing", hole_fairing);
  target_faces = c.read_int(s, "target_faces", target_faces);
  target_edge_length = c.read_double(s, "target_edge_length", target_edge_length);
  smooth_iterations = c.read_int(s, "smooth_iterations", smooth_iterations);
  smooth_time = c.read_double(s, "smooth_time", smooth_time);
  relax_iterations = c.read_int(s, "relax_iterations", relax_iterations);
  orient_closed_outward = c.read_bool(s, "orient_closed_outward", orient_closed_outward);
  recompute_normals = c.read_bool(s, "recompute_normals", recompute_normals);
}

void MeshCleanParams::saveToConfigFile(mrpt::config::CConfigFileBase& c, const std::string& s) const {
  c.write(s, "repair", repair);
  c.write(s, "weld_distance", weld_distance);
  c.write(s, "min_component_faces", min_component_faces);
  c.write(s, "min_component_area", min_component_area);
  c.write(s, "max_hole_perimeter", max_hole_perimeter);
  c.write(s, "max_hole_edges", max_hole_edges);
  c.write(s, "hole_fairing", hole_fairing);
  c.write(s, "target_faces", target_faces);
  c.write(s, "target_edge_length", target_edge_length);
  c.write(s, "smooth_iterations", smooth_iterations);
  c.write(s, "smooth_time", smooth_time);
  c.write(s, "relax_iterations", relax_iterations);
  c.write(s, "orient_closed_outward", orient_closed_outward);
  c.write(s, "recompute_normals", recompute_normals);
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
  char b[32];
  std::snprintf(b, sizeof b, "%.6g", v);
  return b;
}

std::string MeshCleanReport::toJson() const {
  std::ostringstream o;
  o << "{\"success\": " << (success ? "true" : "false");
  if (!success) o << ", \"failure\": " << jsonString(failure);
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
    << ", \"border_cycles_after\": " << border_cycles_after << ", \"closed\": " << (closed ? "true" : "false")
    << ", \"manifold\": " << (manifold ? "true" : "false") << ", \"area\": " << num(area) << "}";
  return o.str();
}

}  // namespace vofusion
