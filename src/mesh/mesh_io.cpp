// OBJ and binary STL writing for TriangleMesh, and writing by file extension (PLY is in ply_io.cpp).
#include <algorithm>
#include <cctype>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>

#include "vofusion/core/atomic_file.h"
#include "vofusion/core/errors.h"
#include "vofusion/mesh/mesh_io.h"

namespace vofusion {
namespace {

void checkIndices(const std::string& path, const TriangleMesh& mesh) {
  for (const auto& f : mesh.faces)
    for (std::uint32_t i : f)
      if (i >= mesh.vertices.size()) throw InputError(path, "mesh face references vertex " + std::to_string(i) + " out of range");
}

void appendf(std::string& out, const char* fmt, double a, double b, double c) {
  char line[128];
  std::snprintf(line, sizeof line, fmt, a, b, c);
  out += line;
}

}  // namespace

void writeObj(const std::string& path, const TriangleMesh& mesh) {
  const std::size_t nv = mesh.vertices.size();
  const bool normals = !mesh.normals.empty(), colors = !mesh.colors.empty();
  if (normals && mesh.normals.size() != nv) throw InputError(path, "mesh has a normal count different from its vertex count");
  if (colors && mesh.colors.size() != nv) throw InputError(path, "mesh has a colour count different from its vertex count");
  checkIndices(path, mesh);
  std::string out = "# written by vofusion\n";
  out.reserve(nv * (colors ? 64 : 40) * (normals ? 2 : 1) + mesh.faces.size() * 40);
  // %.9g: every float comes back bit for bit.
  for (std::size_t i = 0; i < nv; ++i) {
    const auto& v = mesh.vertices[i];
    appendf(out, "v %.9g %.9g %.9g", v.x(), v.y(), v.z());
    if (colors) appendf(out, " %.6g %.6g %.6g", mesh.colors[i][0] / 255.0, mesh.colors[i][1] / 255.0, mesh.colors[i][2] / 255.0);
    out += '\n';
  }
  if (normals)
    for (const auto& n : mesh.normals) appendf(out, "vn %.9g %.9g %.9g\n", n.x(), n.y(), n.z());
  for (const auto& f : mesh.faces) {
    out += 'f';
    for (std::uint32_t i : f) out += ' ' + std::to_string(i + 1) + (normals ? "//" + std::to_string(i + 1) : "");
    out += '\n';
  }
  writeFileAtomically(path, out);
}

void writeStl(const std::string& path, const TriangleMesh& mesh) {
  checkIndices(path, mesh);
  if (mesh.faces.size() > 0xffffffffull) throw InputError(path, "too many faces for STL");
  // The header must not start with "solid": readers would take the file for ASCII STL.
  std::string out(80, '\0');
  const char header[] = "binary STL written by vofusion";
  std::memcpy(out.data(), header, sizeof header - 1);
  const auto put = [&out](const void* p, std::size_t n) { out.append(static_cast<const char*>(p), n); };
  const std::uint32_t count = static_cast<std::uint32_t>(mesh.faces.size());
  put(&count, 4);
  out.reserve(84 + 50 * mesh.faces.size());
  // Little-endian hosts only (x86/ARM), as writePly.
  for (const auto& f : mesh.faces) {
    const Eigen::Vector3f& a = mesh.vertices[f[0]], &b = mesh.vertices[f[1]], &c = mesh.vertices[f[2]];
    Eigen::Vector3f n = (b - a).cross(c - a);
    n = n.norm() > 0 ? Eigen::Vector3f(n.normalized()) : Eigen::Vector3f::Zero();
    put(n.data(), 12);
    put(a.data(), 12);
    put(b.data(), 12);
    put(c.data(), 12);
    const std::uint16_t attribute = 0;
    put(&attribute, 2);
  }
  writeFileAtomically(path, out);
}

MeshFormat meshFormatOf(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  if (ext == ".ply") return MeshFormat::Ply;
  if (ext == ".obj") return MeshFormat::Obj;
  if (ext == ".stl") return MeshFormat::Stl;
  throw InputError(path, (ext.empty() ? std::string("no file extension") : "unknown mesh format '" + ext + "'") +
                             " (the extension must be .ply, .obj or .stl)");
}

void writeMesh(const std::string& path, const TriangleMesh& mesh) { writeMesh(path, mesh, meshFormatOf(path)); }

void writeMesh(const std::string& path, const TriangleMesh& mesh, MeshFormat format) {
  switch (format) {
    case MeshFormat::Ply: writePly(path, mesh); return;
    case MeshFormat::Obj: writeObj(path, mesh); return;
    case MeshFormat::Stl: writeStl(path, mesh); return;
  }
}

}  // namespace vofusion
