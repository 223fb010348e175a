// PLY reading/writing: binary round trip, ASCII input, polygons, malformed and truncated files.
#include <filesystem>
#include <fstream>

#include "support.h"
#include "vofusion/core/allocation_limit.h"
#include "vofusion/core/errors.h"
#include "vofusion/mesh/mesh_io.h"

using namespace vofusion;

namespace {

TriangleMesh tetrahedron(bool normals, bool colors) {
  TriangleMesh m;
  m.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  m.faces = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  if (normals)
    for (const auto& v : m.vertices) m.normals.push_back((v - Eigen::Vector3f(0.25f, 0.25f, 0.25f)).normalized());
  if (colors) m.colors = {{255, 0, 0}, {0, 255, 0}, {0, 0, 255}, {10, 20, 30}};
  return m;
}

void writeText(const std::string& path, const std::string& s) {
  std::ofstream f(path, std::ios::binary);
  f << s;
}

std::string readBytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), {});
}

}  // namespace

TEST(Ply, BinaryRoundTripKeepsEverything) {
  const std::string dir = test::tempDir("ply_roundtrip");
  for (int variant = 0; variant < 4; ++variant) {
    const TriangleMesh m = tetrahedron(variant & 1, variant & 2);
    writePly(dir + "/t.ply", m);
    const TriangleMesh r = readPly(dir + "/t.ply");
    ASSERT_EQ(r.vertices.size(), m.vertices.size());
    ASSERT_EQ(r.faces, m.faces);
    ASSERT_EQ(r.normals.size(), m.normals.size());
    ASSERT_EQ(r.colors, m.colors);
    for (std::size_t i = 0; i < m.vertices.size(); ++i) {
      EXPECT_EQ(r.vertices[i], m.vertices[i]);
      if (!m.normals.empty()) { EXPECT_EQ(r.normals[i], m.normals[i]); }
    }
  }
  // Only the final file is left: no temporaries.
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir), {}), 1);
}

TEST(Ply, WritesBinaryLittleEndianHeader) {
  const std::string dir = test::tempDir("ply_header");
  writePly(dir + "/t.ply", tetrahedron(false, true));
  const std::string s = readBytes(dir + "/t.ply");
  EXPECT_EQ(s.rfind("ply\nformat binary_little_endian 1.0\n", 0), 0u);
  EXPECT_NE(s.find("element vertex 4\n"), std::string::npos);
  EXPECT_NE(s.find("property uchar red\n"), std::string::npos);
  EXPECT_NE(s.find("element face 4\n"), std::string::npos);
  // Body size by hand: 4 vertices * (12 + 3) + 4 faces * (1 + 12).
  EXPECT_EQ(s.size() - (s.find("end_header\n") + 11), 4u * 15 + 4u * 13);
}

TEST(Ply, ReadsAsciiWithQuadsFloatColoursAndExtraElements) {
  const std::string dir = test::tempDir("ply_ascii");
  writeText(dir + "/q.ply",
            "ply\r\nformat ascii 1.0\r\ncomment a quad\r\nelement vertex 4\r\nproperty double x\r\nproperty double y\r\n"
            "property double z\r\nproperty float red\r\nproperty float green\r\nproperty float blue\r\n"
            "property int extra\r\nelement face 1\r\nproperty uchar flags\r\nproperty list uchar uint vertex_index\r\n"
            "element edge 1\r\nproperty int vertex1\r\nproperty int vertex2\r\nend_header\r\n"
            "0 0 0 1 0 0 7\r\n1 0 0 0 1 0 7\r\n1 1 0 0 0 0.5 7\r\n0 1 0 1 1 1 7\r\n5 4 0 1 2 3\r\n0 1\r\n");
  const TriangleMesh m = readPly(dir + "/q.ply");
  ASSERT_EQ(m.vertices.size(), 4u);
  ASSERT_EQ(m.faces.size(), 2u);  // quad -> fan of 2 triangles
  EXPECT_EQ(m.faces[0], (std::array<std::uint32_t, 3>{0, 1, 2}));
  EXPECT_EQ(m.faces[1], (std::array<std::uint32_t, 3>{0, 2, 3}));
  ASSERT_EQ(m.colors.size(), 4u);
  EXPECT_EQ(m.colors[0], (std::array<std::uint8_t, 3>{255, 0, 0}));
  EXPECT_EQ(m.colors[2], (std::array<std::uint8_t, 3>{0, 0, 128}));
  EXPECT_TRUE(m.normals.empty());
  EXPECT_EQ(m.vertices[2], Eigen::Vector3f(1, 1, 0));
}

TEST(Ply, ReadsBigEndian) {
  const std::string dir = test::tempDir("ply_be");
  std::string s = "ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                  "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
  const auto putBE = [&s](const void* p) {
    const char* c = static_cast<const char*>(p);
    for (int i = 3; i >= 0; --i) s += c[i];
  };
  const float coords[9] = {0, 0, 0, 2, 0, 0, 0, 3, 0};
  for (float f : coords) putBE(&f);
  s += char(3);
  for (std::int32_t i : {0, 1, 2}) putBE(&i);
  writeText(dir + "/be.ply", s);
  const TriangleMesh m = readPly(dir + "/be.ply");
  ASSERT_EQ(m.faces.size(), 1u);
  EXPECT_EQ(m.vertices[1], Eigen::Vector3f(2, 0, 0));
  EXPECT_EQ(m.vertices[2], Eigen::Vector3f(0, 3, 0));
}

TEST(Ply, ReadsPclPackedRgb) {
  // PCL writes colour as one float "rgb" whose bits are 0x00RRGGBB, or 0xFFRRGGBB with its alpha: then
  // red 0x80-0xBF makes the bits a signalling NaN, which read as a double came back quieted (red's bit 6 set).
  const std::string dir = test::tempDir("ply_pcl");
  std::string s = "ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                  "property float z\nproperty float rgb\nelement face 1\nproperty list uchar int vertex_indices\n"
                  "end_header\n";
  const std::uint32_t packed[4] = {0x00ff8000u, 0x0000ff00u, 0x00123456u, 0xff804020u};
  for (int i = 0; i < 4; ++i) {
    const float xyz[3] = {float(i), float(i * i), 0.f};
    s.append(reinterpret_cast<const char*>(xyz), 12);
    s.append(reinterpret_cast<const char*>(&packed[i]), 4);
  }
  s += char(3);
  for (std::int32_t i : {0, 1, 2}) s.append(reinterpret_cast<const char*>(&i), 4);
  writeText(dir + "/pcl.ply", s);
  const TriangleMesh m = readPly(dir + "/pcl.ply");
  ASSERT_EQ(m.colors.size(), 4u);
  EXPECT_EQ(m.colors[3], (std::array<std::uint8_t, 3>{0x80, 0x40, 0x20}));
  EXPECT_EQ(m.colors[0], (std::array<std::uint8_t, 3>{0xff, 0x80, 0x00}));
  EXPECT_EQ(m.colors[1], (std::array<std::uint8_t, 3>{0x00, 0xff, 0x00}));
  EXPECT_EQ(m.colors[2], (std::array<std::uint8_t, 3>{0x12, 0x34, 0x56}));
  EXPECT_EQ(m.vertices[2], Eigen::Vector3f(2, 4, 0));
}

TEST(Ply, TruncatedBinaryIsAnInputErrorNamingTheFile) {
  const std::string dir = test::tempDir("ply_trunc");
  writePly(dir + "/t.ply", tetrahedron(true, true));
  const std::string full = readBytes(dir + "/t.ply");
  writeText(dir + "/cut.ply", full.substr(0, full.size() - 5));
  try {
    readPly(dir + "/cut.ply");
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("cut.ply: "), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("truncated"), std::string::npos) << e.what();
  }
}

TEST(Ply, MalformedFilesAreInputErrors) {
  const std::string dir = test::tempDir("ply_bad");
  const std::string head = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                           "element face 1\nproperty list uchar int vertex_indices\nend_header\n";
  const std::pair<const char*, std::string> cases[] = {
      {"magic", "plx\nformat ascii 1.0\nend_header\n"},
      {"noend", "ply\nformat ascii 1.0\nelement vertex 0\n"},
      {"format", "ply\nformat foo 1.0\nend_header\n"},
      {"type", "ply\nformat ascii 1.0\nelement vertex 1\nproperty quad x\nend_header\n"},
      {"range", head + "0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n"},
      {"number", head + "0 0 0\n1 zero 0\n0 1 0\n3 0 1 2\n"},
      {"short", head + "0 0 0\n1 0 0\n0 1 0\n3 0 1\n"},
      {"nan", head + "0 0 0\n1 nan 0\n0 1 0\n3 0 1 2\n"},
      {"nanindex", head + "0 0 0\n1 0 0\n0 1 0\n3 0 1 nan\n"},       // NaN passed the range check as vertex 0
      {"fraction", head + "0 0 0\n1 0 0\n0 1 0\n3 0 1 1.9\n"},       // was vertex 1
      {"nancount", head + "0 0 0\n1 0 0\n0 1 0\nnan 0 1 2\n"},
      {"hugeedges", head.substr(0, head.size() - 11) + "element edge 1000000000000000000\nproperty int vertex1\nend_header\n" +
                        "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"},
      {"novertex", "ply\nformat ascii 1.0\nend_header\n"},
      {"huge", "ply\nformat binary_little_endian 1.0\nelement vertex 99999999999\nproperty float x\nproperty float y\n"
               "property float z\nend_header\n"},
      // end_header without its newline: the body began a byte past the file's end, so the bytes left
      // wrapped round and the count's check passed (bad_alloc, or gigabytes zero-filled).
      {"hugenonl", "ply\nformat binary_little_endian 1.0\nelement vertex 99999999999\nproperty float x\nproperty float y\n"
                   "property float z\nend_header"},
      // A vertex's list count that no integer holds (cast undefined: its values were read as the next ones).
      {"vertexlistcount", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
                          "property list uchar float extra\nend_header\n0 0 0 inf\n"},
      {"vertexlistneg", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
                        "property list int float extra\nend_header\n0 0 0 -1\n"},
      // An integer packed colour that no integer holds (the cast to one was undefined).
      {"packednan", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
                    "property uint rgb\nend_header\n0 0 0 nan\n"},
      {"packedhuge", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
                     "property uint rgb\nend_header\n0 0 0 1e30\n"},
      // A second vertex element after the faces shrank the vertices under them.
      {"twovertex", head.substr(0, head.size() - 11) + "element vertex 1\nproperty float x\nproperty float y\n"
                        "property float z\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n0 0 0\n"},
  };
  for (const auto& [name, text] : cases) {
    const std::string p = dir + "/" + name + ".ply";
    writeText(p, text);
    const ScopedAllocationLimit limit(std::size_t(1) << 30, std::size_t(2) << 30);  // no count sizes a buffer unchecked
    EXPECT_THROW(readPly(p), InputError) << name;
  }
  EXPECT_THROW(readPly(dir + "/missing.ply"), InputError);
  // A device is no mesh: refused, not read without end (without the refusal: bad_alloc at the limit).
  try {
    const ScopedAllocationLimit limit(std::size_t(1) << 30, std::size_t(2) << 30);
    readPly("/dev/zero");
    ADD_FAILURE() << "/dev/zero read as a mesh";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), "/dev/zero: is not a regular file or a pipe, expected a PLY mesh");
  }
  // A pipe is a mesh's too (vofusion-mesh <(zcat m.ply.gz)).
  writePly(dir + "/t.ply", tetrahedron(false, false));
  std::string out;
  // The writer in the background with none of run()'s output (which would wait for it), as a shell's
  // process substitution is.
  ASSERT_EQ(test::run("mkfifo " + dir + "/pipe && ((exec >/dev/null 2>&1 </dev/null; cat " + dir + "/t.ply > " + dir + "/pipe) &) && echo made",
                      &out),
            0)
      << out;
  EXPECT_EQ(readPly(dir + "/pipe").faces.size(), 4u);
  // An element without properties holds no bytes, however many it announces: read at once (a loop over
  // 10^18 of them did nothing for as long).
  writeText(dir + "/empty_elements.ply", head.substr(0, head.size() - 11) + "element edge 1000000000000000000\nend_header\n" +
                                             "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  EXPECT_EQ(readPly(dir + "/empty_elements.ply").faces.size(), 1u);
}

// Tools write NaN normals for unreferenced vertices (MeshLab): the file's normals are dropped, for
// whoever needs them to compute from the faces; a NaN normal shaded its vertex black in the scene.
TEST(Ply, ANonFiniteNormalDropsTheFilesNormals) {
  const std::string dir = test::tempDir("ply_nan_normal");
  writeText(dir + "/n.ply", "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
                            "property float nx\nproperty float ny\nproperty float nz\nproperty uint rgb\n"
                            "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
                            "0 0 0 0 0 1 16711680\n1 0 0 0 0 1 65280\n0 1 0 0 0 1 255\n5 5 5 nan nan nan 0\n3 0 1 2\n");
  const TriangleMesh m = readPly(dir + "/n.ply");
  EXPECT_EQ(m.vertices.size(), 4u);
  EXPECT_TRUE(m.normals.empty());
  ASSERT_EQ(m.colors.size(), 4u);
  EXPECT_EQ(m.colors[0], (std::array<std::uint8_t, 3>{255, 0, 0}));
  EXPECT_EQ(m.colors[2], (std::array<std::uint8_t, 3>{0, 0, 255}));
}

// PLY puts elements in any order. Faces before the vertices they name were refused as "references vertex
// 0 out of range"; and an index no integer holds went through a cast to long long (undefined).
TEST(Ply, FacesBeforeTheirVerticesAreRead) {
  const std::string dir = test::tempDir("ply_order");
  writeText(dir + "/faces_first.ply",
            "ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_indices\nelement vertex 3\n"
            "property float x\nproperty float y\nproperty float z\nend_header\n3 0 1 2\n0 0 0\n1 0 0\n0 1 0\n");
  const TriangleMesh m = readPly(dir + "/faces_first.ply");
  ASSERT_EQ(m.vertices.size(), 3u);
  ASSERT_EQ(m.faces.size(), 1u);
  EXPECT_EQ(m.faces[0], (std::array<std::uint32_t, 3>{0, 1, 2}));
  writeText(dir + "/huge_index.ply",
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
            "element face 1\nproperty list uchar double vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 1e19\n");
  try {
    readPly(dir + "/huge_index.ply");
    ADD_FAILURE() << "read";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("face 0 references vertex 1e+19 out of range (3 vertices)"), std::string::npos) << e.what();
  }
}

// A header's counts are held against the bytes each record needs at least, before they size a buffer:
// 2 MB claiming 2 million vertices of 27 bytes (54 MB zero-filled) is refused as truncated at once.
TEST(Ply, ACountTheBytesCannotHoldAllocatesNothing) {
  const std::string dir = test::tempDir("ply_count_bomb");
  const std::string p = dir + "/bomb.ply";
  std::string text = "ply\nformat binary_little_endian 1.0\nelement vertex 2000000\nproperty float x\nproperty float y\n"
                     "property float z\nproperty float nx\nproperty float ny\nproperty float nz\nproperty uchar red\n"
                     "property uchar green\nproperty uchar blue\nend_header\n";
  text += std::string(2000000, '\0');
  writeText(p, text);
  const ScopedAllocationLimit limit(std::size_t(8) << 20, std::size_t(16) << 20);  // the file's 2 MB, twice, and more
  try {
    readPly(p);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("file is truncated (header announces 2000000 vertices)"), std::string::npos) << e.what();
  }
}

// The same for faces: a face's list holds its count and at least 3 indices, so 2 MB cannot hold 2 M
// faces of a uchar count and int indices (reserving them took 24 MB: only the count's byte was counted).
TEST(Ply, AFaceCountTheBytesCannotHoldAllocatesNothing) {
  const std::string dir = test::tempDir("ply_face_count_bomb");
  const std::string p = dir + "/bomb.ply";
  std::string text = "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                     "property float z\nelement face 2000000\nproperty list uchar int vertex_indices\nend_header\n";
  text += std::string(3 * 12, '\0') + std::string(2000000, '\0');
  writeText(p, text);
  const ScopedAllocationLimit limit(std::size_t(8) << 20, std::size_t(16) << 20);
  try {
    readPly(p);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("file is truncated (header announces 2000000 faces)"), std::string::npos) << e.what();
  }
}

TEST(Ply, FailedWriteKeepsEarlierFile) {
  const std::string dir = test::tempDir("ply_atomic");
  writePly(dir + "/t.ply", tetrahedron(false, false));
  TriangleMesh bad = tetrahedron(false, false);
  bad.faces.push_back({0, 1, 99});
  EXPECT_THROW(writePly(dir + "/t.ply", bad), InputError);
  EXPECT_EQ(readPly(dir + "/t.ply").faces.size(), 4u);
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir), {}), 1);
}
