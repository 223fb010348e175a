#pragma once
// Mesh files: PLY (read and write), OBJ and STL (write).
#include <string>

#include "vofusion/core/triangle_mesh.h"

namespace vofusion {

// Binary little-endian PLY (vertex x y z [nx ny nz] [red green blue], face vertex_indices);
// written whole or not at all. readPly also accepts ASCII PLY; throws InputError on bad files.
void writePly(const std::string& path, const TriangleMesh& mesh);
TriangleMesh readPly(const std::string& path);

// Wavefront OBJ (text): "v x y z [r g b]" with colours in [0, 1] (the common extension MeshLab and
// Open3D read), "vn" normals when present, 1-based "f" lines. Written whole or not at all.
void writeObj(const std::string& path, const TriangleMesh& mesh);
// Binary STL: geometry only (STL has no vertex colours), a face normal per triangle.
void writeStl(const std::string& path, const TriangleMesh& mesh);

enum class MeshFormat { Ply, Obj, Stl };
// The format named by the path's extension (.ply, .obj, .stl, any case); InputError naming the file
// otherwise.
MeshFormat meshFormatOf(const std::string& path);
// Writes PLY, OBJ or STL by the extension of `path`.
void writeMesh(const std::string& path, const TriangleMesh& mesh);
// The same in the given format, whatever the path's extension (a temporary of the file asked for).
void writeMesh(const std::string& path, const TriangleMesh& mesh, MeshFormat format);

}  // namespace vofusion
