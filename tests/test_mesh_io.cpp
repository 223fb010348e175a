// OBJ and STL writing, the format chosen by the file extension, and vofusion-mesh writing each.
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "support.h"
#include "test_mesh_fixtures.h"
#include "vofusion/core/atomic_file.h"
#include "vofusion/core/errors.h"
#include "vofusion/mesh/mesh_io.h"

using namespace vofusion;

namespace {

TriangleMesh tetrahedron() {
  TriangleMesh m;
  m.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0.125f, 0.3f, 1.7f}};
  m.faces = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  for (const auto& v : m.vertices) m.normals.push_back((v - Eigen::Vector3f(0.25f, 0.25f, 0.25f)).normalized());
  m.colors = {{255, 0, 0}, {0, 255, 0}, {0, 0, 255}, {10, 20, 30}};
  return m;
}

std::string readBytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), {});
}

// A minimal reader for what writeObj writes: "v x y z [r g b]", "vn", "f a[//n] b c".
TriangleMesh parseObj(const std::string& text) {
  TriangleMesh m;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream ls(line);
    std::string kw;
    ls >> kw;
    if (kw == "v") {
      float x, y, z, r, g, b;
      ls >> x >> y >> z;
      m.vertices.emplace_back(x, y, z);
      if (ls >> r >> g >> b)
        m.colors.push_back({std::uint8_t(std::lround(r * 255)), std::uint8_t(std::lround(g * 255)), std::uint8_t(std::lround(b * 255))});
    } else if (kw == "vn") {
      float x, y, z;
      ls >> x >> y >> z;
      m.normals.emplace_back(x, y, z);
    } else if (kw == "f") {
      std::array<std::uint32_t, 3> f{};
      for (auto& i : f) {
        std::string tok;
        ls >> tok;
        i = std::uint32_t(std::stoul(tok)) - 1;  // stoul stops at "//"
      }
      m.faces.push_back(f);
    }
  }
  return m;
}

}  // namespace

TEST(MeshIo, ObjRoundTripKeepsPositionsNormalsColoursAndFaces) {
  const std::string dir = test::tempDir("obj_roundtrip");
  const TriangleMesh m = tetrahedron();
  writeObj(dir + "/t.obj", m);
  const std::string text = readBytes(dir + "/t.obj");
  EXPECT_NE(text.find("\nv 1 0 0 0 1 0\n"), std::string::npos) << text;  // colour as the "v x y z r g b" extension
  EXPECT_NE(text.find("\nf 1//1 3//3 2//2\n"), std::string::npos) << text;  // 1-based, with normals
  const TriangleMesh r = parseObj(text);
  EXPECT_EQ(r.faces, m.faces);
  EXPECT_EQ(r.colors, m.colors);
  ASSERT_EQ(r.vertices.size(), m.vertices.size());
  ASSERT_EQ(r.normals.size(), m.normals.size());
  for (std::size_t i = 0; i < m.vertices.size(); ++i) {
    EXPECT_EQ(r.vertices[i], m.vertices[i]);  // bit for bit
    EXPECT_EQ(r.normals[i], m.normals[i]);
  }

  TriangleMesh bare = m;  // no colours, no normals: plain "v x y z" and "f a b c"
  bare.colors.clear();
  bare.normals.clear();
  writeObj(dir + "/bare.obj", bare);
  const std::string bare_text = readBytes(dir + "/bare.obj");
  EXPECT_NE(bare_text.find("\nv 1 0 0\n"), std::string::npos) << bare_text;
  EXPECT_NE(bare_text.find("\nf 1 3 2\n"), std::string::npos) << bare_text;
  EXPECT_EQ(bare_text.find("vn "), std::string::npos);
}

TEST(MeshIo, StlIsBinaryWithAFaceNormalPerTriangle) {
  const std::string dir = test::tempDir("stl");
  const TriangleMesh m = tetrahedron();
  writeStl(dir + "/t.stl", m);
  const std::string b = readBytes(dir + "/t.stl");
  ASSERT_EQ(b.size(), 84u + 50u * m.faces.size());
  EXPECT_NE(b.compare(0, 5, "solid"), 0);  // else readers take it for ASCII STL
  std::uint32_t count;
  std::memcpy(&count, b.data() + 80, 4);
  EXPECT_EQ(count, m.faces.size());
  for (std::size_t t = 0; t < m.faces.size(); ++t) {
    float f[12];
    std::memcpy(f, b.data() + 84 + 50 * t, 48);
    const Eigen::Vector3f n(f[0], f[1], f[2]);
    for (int k = 0; k < 3; ++k) EXPECT_EQ(Eigen::Vector3f(f[3 + 3 * k], f[4 + 3 * k], f[5 + 3 * k]), m.vertices[m.faces[t][k]]);
    const Eigen::Vector3f& a = m.vertices[m.faces[t][0]];
    const Eigen::Vector3f expected = (m.vertices[m.faces[t][1]] - a).cross(m.vertices[m.faces[t][2]] - a).normalized();
    EXPECT_LT((n - expected).norm(), 1e-6f) << "triangle " << t;
  }
}

TEST(MeshIo, FormatFollowsTheExtension) {
  const std::string dir = test::tempDir("mesh_ext");
  const TriangleMesh m = tetrahedron();
  writeMesh(dir + "/a.ply", m);
  writeMesh(dir + "/a.OBJ", m);
  writeMesh(dir + "/a.stl", m);
  EXPECT_EQ(readPly(dir + "/a.ply").faces, m.faces);
  EXPECT_EQ(readBytes(dir + "/a.OBJ"), (writeObj(dir + "/b.obj", m), readBytes(dir + "/b.obj")));
  EXPECT_EQ(readBytes(dir + "/a.stl").size(), 84u + 50u * m.faces.size());

  for (const std::string bad : {"/a.off", "/noext"}) {
    try {
      writeMesh(dir + bad, m);
      ADD_FAILURE() << "no error for " << bad;
    } catch (const InputError& e) {
      const std::string what = e.what();
      EXPECT_EQ(what.rfind(dir + bad + ": ", 0), 0u) << what;  // names the file first
      EXPECT_EQ(what.find('\n'), std::string::npos) << what;
      EXPECT_NE(what.find(".ply, .obj or .stl"), std::string::npos) << what;
    }
    EXPECT_FALSE(std::filesystem::exists(dir + bad));
  }
}

TEST(MeshIo, VofusionMeshWritesObjAndStlAndRejectsOtherExtensions) {
  const std::string dir = test::tempDir("mesh_app_formats");
  writePly(dir + "/in.ply", test::icosphere(2, 0.2f));
  std::string out;
  ASSERT_EQ(test::run(test::app("vofusion-mesh") + " " + dir + "/in.ply " + dir + "/out.obj --full " + dir + "/full.stl", &out), 0)
      << out;
  const TriangleMesh obj = parseObj(readBytes(dir + "/out.obj"));
  EXPECT_GT(obj.faces.size(), 0u);
  EXPECT_EQ(obj.colors.size(), obj.vertices.size());
  EXPECT_EQ(readBytes(dir + "/full.stl").size(), 84u + 50u * test::icosphere(2).faces.size());  // not simplified

  EXPECT_EQ(test::run(test::app("vofusion-mesh") + " " + dir + "/in.ply " + dir + "/out.xyz", &out), 2);
  EXPECT_NE(out.find(dir + "/out.xyz: unknown mesh format '.xyz'"), std::string::npos) << out;
  EXPECT_EQ(std::count(out.begin(), out.end(), '\n'), 1) << out;
  EXPECT_FALSE(std::filesystem::exists(dir + "/out.xyz"));

  // One file named for two outputs: refused before any work, the earlier file as it was (the second
  // output's temporary replaced the first's, and the full mesh was put in place as out.obj).
  const std::string before = readBytes(dir + "/out.obj");
  EXPECT_EQ(test::run(test::app("vofusion-mesh") + " " + dir + "/in.ply " + dir + "/out.obj --full " + dir + "/./out.obj", &out), 2);
  EXPECT_NE(out.find(dir + "/./out.obj: named twice as an output"), std::string::npos) << out;
  EXPECT_EQ(readBytes(dir + "/out.obj"), before);
}

// The same refusal for any set of outputs moved into place together.
TEST(MeshIo, AnOutputSetRefusesAFileNamedTwice) {
  const std::string dir = test::tempDir("mesh_set_twice");
  AtomicFileSet set;
  set.write(dir + "/a.ply", [](const std::string& tmp) { std::ofstream(tmp) << "a"; });
  EXPECT_THROW(set.write(dir + "/../mesh_set_twice/a.ply", [](const std::string& tmp) { std::ofstream(tmp) << "b"; }), InputError);
  set.commit();
  EXPECT_EQ(readBytes(dir + "/a.ply"), "a");
}
