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
  c.write(s, "repair", repair, -1, 1, "merge duplicates, drop degenerate/duplicate faces, orient, make manifold, stitch");
  c.write(s, "weld_distance", weld_distance, -1, 1, "m, also merge vertices closer than this (0: exact duplicates only)");
  c.write(s, "min_component_faces", min_component_faces, -1, 1, "faces, smaller connected components are removed (0: off)");
  c.write(s, "min_component_area", min_component_area, -1, 1, "m^2, smaller connected components are removed (0: off)");
  c.write(s, "max_hole_perimeter", max_hole_perimeter, -1, 1, "m, longer hole borders stay open (0: fill no holes)");
  c.write(s, "max_hole_edges", max_hole_edges, -1, 1, "edges, hole borders with more edges stay open");
  c.write(s, "hole_fairing", hole_fairing, -1, 1, "fair (smooth) hole patches; false: flat refined patch");
  c.write(s, "target_faces", target_faces, -1, 1, "faces, edge-collapse simplification target (0: off)");
  c.write(s, "target_edge_length", target_edge_length, -1, 1, "m, simplify until no shorter edge is left (0: off)");
  c.write(s, "smooth_iterations", smooth_iterations, -1, 1, "iterations of curvature-flow shape smoothing (0: off)");
  c.write(s, "smooth_time", smooth_time, -1, 1, "time step of the curvature flow per iteration");
  c.write(s, "relax_iterations", relax_iterations, -1, 1, "iterations of tangential relaxation (0: off)");
  c.write(s, "orient_closed_outward", orient_closed_outward, -1, 1, "orient closed results with normals outward");
  c.write(s, "recompute_normals", recompute_normals, -1, 1, "write fresh vertex normals (false: none written)");
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
