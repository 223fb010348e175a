// PLY reading (ASCII, binary little/big endian) and binary little-endian writing for TriangleMesh.
#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "vofusion/core/atomic_file.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/progress.h"
#include "vofusion/core/text_file.h"
#include "vofusion/mesh/mesh_io.h"

namespace vofusion {
namespace {

enum class Scalar { Int8, UInt8, Int16, UInt16, Int32, UInt32, Float32, Float64 };

bool parseScalar(const std::string& s, Scalar& out) {
  static const std::pair<const char*, Scalar> names[] = {
      {"char", Scalar::Int8},     {"int8", Scalar::Int8},      {"uchar", Scalar::UInt8},   {"uint8", Scalar::UInt8},
      {"short", Scalar::Int16},   {"int16", Scalar::Int16},    {"ushort", Scalar::UInt16}, {"uint16", Scalar::UInt16},
      {"int", Scalar::Int32},     {"int32", Scalar::Int32},    {"uint", Scalar::UInt32},   {"uint32", Scalar::UInt32},
      {"float", Scalar::Float32}, {"float32", Scalar::Float32}, {"double", Scalar::Float64}, {"float64", Scalar::Float64}};
  for (const auto& [n, t] : names)
    if (s == n) { out = t; return true; }
  return false;
}

std::size_t scalarSize(Scalar t) {
  switch (t) {
    case Scalar::Int8: case Scalar::UInt8: return 1;
    case Scalar::Int16: case Scalar::UInt16: return 2;
    case Scalar::Int32: case Scalar::UInt32: case Scalar::Float32: return 4;
    case Scalar::Float64: return 8;
  }
  return 0;
}

struct Property {
  std::string name;
  bool is_list = false;
  Scalar count_type = Scalar::UInt8, type = Scalar::Float32;
};

struct Element {
  std::string name;
  std::size_t count = 0;
  std::vector<Property> props;
};

enum class Format { Ascii, BinaryLE, BinaryBE };

// Sequential reader of scalar values over the body of the file, in either encoding.
class BodyReader {
 public:
  BodyReader(const std::string& path, const std::string& data, std::size_t pos, Format fmt)
      : path_(path), data_(data), pos_(pos), fmt_(fmt) {}

  double read(Scalar t, const char* what) {
    if (fmt_ == Format::Ascii) return readAscii(what);
    const std::size_t n = scalarSize(t);
    if (pos_ + n > data_.size()) throw InputError(path_, std::string("file is truncated (while reading ") + what + ")");
    unsigned char b[8];
    std::memcpy(b, data_.data() + pos_, n);
    pos_ += n;
    if (fmt_ == Format::BinaryBE)
      for (std::size_t i = 0; i < n / 2; ++i) std::swap(b[i], b[n - 1 - i]);
    switch (t) {
      case Scalar::Int8: { std::int8_t v; std::memcpy(&v, b, 1); return v; }
      case Scalar::UInt8: return b[0];
      case Scalar::Int16: { std::int16_t v; std::memcpy(&v, b, 2); return v; }
      case Scalar::UInt16: { std::uint16_t v; std::memcpy(&v, b, 2); return v; }
      case Scalar::Int32: { std::int32_t v; std::memcpy(&v, b, 4); return v; }
      case Scalar::UInt32: { std::uint32_t v; std::memcpy(&v, b, 4); return v; }
      case Scalar::Float32: { float v; std::memcpy(&v, b, 4); std::memcpy(&last_float_bits_, b, 4); return v; }
      case Scalar::Float64: { double v; std::memcpy(&v, b, 8); return v; }
    }
    return 0;
  }

  // Whether `count` records of `e` can fit in the bytes left: each takes at least its scalars' sizes (a
  // list its count's) in binary, a character and a separator per value in ASCII. Checked before a
  // count sizes a buffer: a damaged header must not allocate gigabytes before the read fails.
  // `polygon`: the index of a list that holds at least 3 values (a face's vertex indices; a face
  // reserves 12 bytes where its count alone took 1).
  bool fits(const Element& e, int polygon = -1) const {
    std::size_t least = 0;
    for (const Property& p : e.props) least += fmt_ == Format::Ascii ? 2 : scalarSize(p.is_list ? p.count_type : p.type);
    if (polygon >= 0) least += 3 * (fmt_ == Format::Ascii ? 2 : scalarSize(e.props[std::size_t(polygon)].type));
    const std::size_t left = data_.size() - pos_ + (fmt_ == Format::Ascii ? 1 : 0);  // the last value needs no separator
    return least == 0 || e.count <= left / least;
  }

  // The bits of the last binary float read, as the file holds them: a packed colour's (PCL's "float
  // rgb"), which the double read() returns cannot carry when they are a signalling NaN (alpha 0xFF, red
  // 0x80-0xBF: widening quiets it, and set red's bit 6).
  std::uint32_t lastFloatBits() const { return last_float_bits_; }
  bool binary() const { return fmt_ != Format::Ascii; }

 private:
  std::uint32_t last_float_bits_ = 0;
  double readAscii(const char* what) {
    while (pos_ < data_.size() && std::isspace(static_cast<unsigned char>(data_[pos_]))) ++pos_;
    if (pos_ >= data_.size()) throw InputError(path_, std::string("file is truncated (while reading ") + what + ")");
    std::size_t end = pos_;
    while (end < data_.size() && !std::isspace(static_cast<unsigned char>(data_[end]))) ++end;
    const std::string tok = data_.substr(pos_, end - pos_);
    pos_ = end;
    char* stop = nullptr;
    const double v = std::strtod(tok.c_str(), &stop);
    if (stop == tok.c_str() || *stop != '\0')
      throw InputError(path_, std::string("bad number '") + tok + "' (while reading " + what + ")");
    return v;
  }

  const std::string& path_;
  const std::string& data_;
  std::size_t pos_;
  Format fmt_;
};

std::string slurp(const std::string& path) {
  // A mesh is a file or a pipe (<(zcat m.ply.gz)); a device (/dev/zero) would be read without end,
  // and a pipe is read up to 4 GiB.
  std::error_code ec;
  const bool pipe = std::filesystem::is_fifo(path, ec);
  if (std::filesystem::exists(path, ec) && !std::filesystem::is_regular_file(path, ec) && !pipe)
    throw InputError(path, "is not a regular file or a pipe, expected a PLY mesh");
  if (pipe) {
    std::ifstream f(path, std::ios::binary);
    if (!f) throw InputError(path, "cannot open file");
    return readCapped(f, path, std::size_t(4) << 30, "4 GiB", "a mesh");
  }
  std::ifstream f(path, std::ios::binary);
  if (!f) throw InputError(path, "cannot open file");
  std::ostringstream ss;
  ss << f.rdbuf();
  if (f.bad()) throw InputError(path, "read error");
  return ss.str();
}

int indexOf(const Element& e, const std::string& name) {
  for (std::size_t i = 0; i < e.props.size(); ++i)
    if (e.props[i].name == name) return static_cast<int>(i);
  return -1;
}

// Builds the error for a bad header line, naming the file and the line.
struct HeaderError {
  const std::string& path;
  int line_no;
  InputError operator()(const std::string& what) const {
    return InputError(path, "header line " + std::to_string(line_no) + ": " + what);
  }
};

struct Header {
  Format fmt = Format::Ascii;
  std::vector<Element> elements;
  std::size_t body = 0;  // offset of the first byte after the end_header line
};

// The rest of a "format <encoding> <version>" line.
Format parseFormat(std::istringstream& ls, const HeaderError& bad) {
  std::string f, ver;
  ls >> f >> ver;
  if (f == "ascii") return Format::Ascii;
  if (f == "binary_little_endian") return Format::BinaryLE;
  if (f == "binary_big_endian") return Format::BinaryBE;
  throw bad("unknown format '" + f + "'");
}

// The rest of a "property <type> <name>" or "property list <count type> <value type> <name>" line.
Property parseProperty(std::istringstream& ls, const HeaderError& bad) {
  Property p;
  std::string t;
  ls >> t;
  if (t == "list") {
    std::string ct, vt;
    ls >> ct >> vt >> p.name;
    if (!parseScalar(ct, p.count_type) || !parseScalar(vt, p.type)) throw bad("unknown list type");
    p.is_list = true;
  } else {
    if (!parseScalar(t, p.type)) throw bad("unknown property type '" + t + "'");
    ls >> p.name;
  }
  if (p.name.empty()) throw bad("property without a name");
  return p;
}

// Header: line by line up to "end_header".
Header readHeader(const std::string& path, const std::string& data) {
  Header h;
  std::size_t pos = 0;
  bool have_format = false, ended = false;
  for (int line_no = 1; pos < data.size(); ++line_no) {
    std::size_t eol = data.find('\n', pos);
    if (eol == std::string::npos) eol = data.size();
    std::string line = data.substr(pos, eol - pos);
    pos = eol + 1;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    std::istringstream ls(line);
    std::string kw;
    ls >> kw;
    const HeaderError bad{path, line_no};
    if (kw == "ply" || kw == "comment" || kw == "obj_info" || kw.empty()) continue;
    if (kw == "end_header") { ended = true; break; }
    if (kw == "format") {
      h.fmt = parseFormat(ls, bad);
      have_format = true;
    } else if (kw == "element") {
      Element e;
      long long n = -1;
      if (!(ls >> e.name >> n) || n < 0) throw bad("expected 'element <name> <count>'");
      e.count = static_cast<std::size_t>(n);
      h.elements.push_back(e);
    } else if (kw == "property") {
      if (h.elements.empty()) throw bad("property before any element");
      h.elements.back().props.push_back(parseProperty(ls, bad));
    } else {
      throw bad("unknown keyword '" + kw + "'");
    }
  }
  if (!ended) throw InputError(path, "PLY header has no end_header");
  if (!have_format) throw InputError(path, "PLY header has no format line");
  h.body = std::min(pos, data.size());  // an end_header without its newline ends the file: the body is empty, not past it
  return h;
}

// Which properties of a vertex element hold the coordinates, normals and colours (-1: none).
struct VertexLayout {
  int ix, iy, iz, inx, iny, inz, ir, ig, ib, ipacked;
  bool normals, packed, colors;
};

VertexLayout vertexLayout(const std::string& path, const Element& e) {
  VertexLayout l;
  l.ix = indexOf(e, "x"); l.iy = indexOf(e, "y"); l.iz = indexOf(e, "z");
  if (l.ix < 0 || l.iy < 0 || l.iz < 0) throw InputError(path, "vertex element lacks x, y or z");
  l.inx = indexOf(e, "nx"); l.iny = indexOf(e, "ny"); l.inz = indexOf(e, "nz");
  l.ir = indexOf(e, "red"); l.ig = indexOf(e, "green"); l.ib = indexOf(e, "blue");
  if (l.ir < 0) { l.ir = indexOf(e, "r"); l.ig = indexOf(e, "g"); l.ib = indexOf(e, "b"); }
  l.normals = l.inx >= 0 && l.iny >= 0 && l.inz >= 0;
  // PCL-style packed colour: "rgb" (float or uint bits 0x00RRGGBB) or "rgba" (uint 0xAARRGGBB).
  l.ipacked = indexOf(e, "rgb");
  if (l.ipacked < 0) l.ipacked = indexOf(e, "rgba");
  l.packed = l.ir < 0 && l.ipacked >= 0 && !e.props[l.ipacked].is_list &&
             scalarSize(e.props[l.ipacked].type) == 4;
  l.colors = (l.ir >= 0 && l.ig >= 0 && l.ib >= 0) || l.packed;
  return l;
}

// A vertex's colour from its property values `v`: packed bits, or channels in 0..255 (0..1 when float).
std::array<std::uint8_t, 3> vertexColour(const Element& e, const VertexLayout& l, const std::vector<double>& v,
                                         const std::optional<std::uint32_t>& packed_bits) {
  const bool unit = !l.packed && (e.props[l.ir].type == Scalar::Float32 || e.props[l.ir].type == Scalar::Float64);
  const auto to8 = [&](double c) {
    const double s = unit ? c * 255.0 : c;
    return static_cast<std::uint8_t>(std::lround(std::min(255.0, std::max(0.0, s))));
  };
  if (l.packed) {
    std::uint32_t bits;
    if (packed_bits) {
      bits = *packed_bits;
    } else if (e.props[l.ipacked].type == Scalar::Float32) {  // ASCII: the value as written
      const float f = static_cast<float>(v[l.ipacked]);
      std::memcpy(&bits, &f, 4);
    } else {
      bits = static_cast<std::uint32_t>(static_cast<std::int64_t>(v[l.ipacked]));
    }
    return {std::uint8_t(bits >> 16), std::uint8_t(bits >> 8), std::uint8_t(bits)};
  }
  return {to8(v[l.ir]), to8(v[l.ig]), to8(v[l.ib])};
}

// A number read from the file as it was written ("5", "-1", "1e+19", "nan"), for a message.
std::string numberText(double x) {
  char text[32];
  std::snprintf(text, sizeof text, "%.17g", x);
  return text;
}

// Reads the body element by element into a mesh.
struct BodyParser {
  BodyParser(const std::string& path, const std::string& data, const Header& h)
      : path(path), data(data), body(path, data, h.body, h.fmt) {
    // PLY puts elements in any order: faces may come before the vertices they name, whose number the
    // header gives.
    for (const Element& e : h.elements)
      if (e.name == "vertex") {
        vertex_count = e.count;
        break;
      }
  }

  const std::string& path;
  const std::string& data;
  BodyReader body;
  TriangleMesh mesh;
  bool have_vertices = false;
  std::optional<std::size_t> vertex_count;  // the header's

  // A list's count, read (`what` for a truncation's message): a whole number up to a million, or the
  // file's error naming record `i` of `kind`. Written so that NaN (an ASCII "nan", a float list) fails
  // too; a fraction, inf, a negative are no count.
  std::size_t listCount(const Property& p, const char* what, const char* kind, std::size_t i, const char* count_of) {
    const double nd = body.read(p.count_type, what);
    if (!(nd >= 0 && nd <= 1e6) || nd != std::floor(nd))
      throw InputError(path, std::string(kind) + " " + std::to_string(i) + " has a bad " + count_of + " count");
    return static_cast<std::size_t>(nd);
  }

  void readVertices(const Element& e) {
    const VertexLayout l = vertexLayout(path, e);
    // A second vertex element would resize the first's vertices under the faces already read.
    if (have_vertices) throw InputError(path, "more than one vertex element");
    if (!body.fits(e))
      throw InputError(path, "file is truncated (header announces " + std::to_string(e.count) + " vertices)");
    mesh.vertices.resize(e.count);
    if (l.normals) mesh.normals.resize(e.count);
    if (l.colors) mesh.colors.resize(e.count);
    std::vector<double> v(e.props.size());
    std::optional<std::uint32_t> packed_bits;  // a binary float packed colour's own bits
    std::optional<std::size_t> bad_normal;      // the first vertex whose normal is not finite
    for (std::size_t i = 0; i < e.count; ++i) {
      for (std::size_t k = 0; k < e.props.size(); ++k) {
        const Property& p = e.props[k];
        if (p.is_list) {  // unusual on vertices, but skip it properly
          const std::size_t n = listCount(p, "vertex list", "vertex", i, "list");
          for (std::size_t j = 0; j < n; ++j) body.read(p.type, "vertex list");
          v[k] = 0;
        } else {
          v[k] = body.read(p.type, "vertices");
          if (l.packed && int(k) == l.ipacked && p.type == Scalar::Float32 && body.binary()) packed_bits = body.lastFloatBits();
        }
      }
      mesh.vertices[i] = Eigen::Vector3f(float(v[l.ix]), float(v[l.iy]), float(v[l.iz]));
      if (!mesh.vertices[i].allFinite())
        throw InputError(path, "vertex " + std::to_string(i) + " has a non-finite coordinate");
      if (l.normals) mesh.normals[i] = Eigen::Vector3f(float(v[l.inx]), float(v[l.iny]), float(v[l.inz]));
      if (l.normals && !mesh.normals[i].allFinite() && !bad_normal) bad_normal = i;
      // An integer packed colour written as text can be anything ("nan", "1e30"): cast, undefined.
      if (l.colors && l.packed && !packed_bits && e.props[l.ipacked].type != Scalar::Float32 &&
          !(v[l.ipacked] >= -2147483648.0 && v[l.ipacked] <= 4294967295.0))
        throw InputError(path, "vertex " + std::to_string(i) + " has a packed colour out of range (" +
                                   numberText(v[l.ipacked]) + ")");
      if (l.colors) mesh.colors[i] = vertexColour(e, l, v, packed_bits);
    }
    // Tools write NaN normals for unreferenced or degenerate vertices: the normals are dropped, and
    // whoever needs them computes them from the faces (a NaN normal shaded its vertex black).
    if (bad_normal) {
      printWarning(path + ": vertex " + std::to_string(*bad_normal) + " has a non-finite normal: the file's normals are not used");
      mesh.normals.clear();
    }
    have_vertices = true;
  }

  void readFaces(const Element& e) {
    int il = indexOf(e, "vertex_indices");
    if (il < 0) il = indexOf(e, "vertex_index");
    if (il < 0 || !e.props[il].is_list) throw InputError(path, "face element lacks a vertex_indices list");
    if (!body.fits(e, il))
      throw InputError(path, "file is truncated (header announces " + std::to_string(e.count) + " faces)");
    mesh.faces.reserve(e.count);
    std::vector<std::uint32_t> poly;
    for (std::size_t i = 0; i < e.count; ++i) {
      for (std::size_t k = 0; k < e.props.size(); ++k) {
        const Property& p = e.props[k];
        if (!p.is_list) { body.read(p.type, "faces"); continue; }
        const std::size_t n = listCount(p, "faces", "face", i, "vertex");
        poly.clear();
        for (std::size_t j = 0; j < n; ++j) {
          const double idx = body.read(p.type, "faces");
          if (static_cast<int>(k) != il) continue;
          if (!vertex_count) throw InputError(path, "PLY has no vertex element");
          if (!(idx >= 0 && idx < static_cast<double>(*vertex_count)))
            throw InputError(path, "face " + std::to_string(i) + " references vertex " + numberText(idx) +
                                       " out of range (" + std::to_string(*vertex_count) + " vertices)");
          if (idx != std::floor(idx))  // "1.9" was vertex 1
            throw InputError(path, "face " + std::to_string(i) + " references vertex " + numberText(idx) +
                                       " (not a whole number)");
          poly.push_back(static_cast<std::uint32_t>(idx));
        }
        if (static_cast<int>(k) != il) continue;
        if (n < 3) throw InputError(path, "face " + std::to_string(i) + " has fewer than 3 vertices");
        for (std::size_t j = 1; j + 1 < n; ++j) mesh.faces.push_back({poly[0], poly[j], poly[j + 1]});  // fan
      }
    }
  }

  // Unknown element (edges, materials...): read and discard.
  void skipElement(const Element& e) {
    // Each record takes at least a byte (a list its count), so more records than bytes left is a lie;
    // an element without properties is nothing to read however many it announces.
    if (e.props.empty()) return;
    if (e.count > data.size())
      throw InputError(path, "file is truncated (header announces " + std::to_string(e.count) + " " + e.name + ")");
    for (std::size_t i = 0; i < e.count; ++i)
      for (const Property& p : e.props) {
        if (!p.is_list) { body.read(p.type, e.name.c_str()); continue; }
        const std::size_t n = listCount(p, e.name.c_str(), e.name.c_str(), i, "list");
        for (std::size_t j = 0; j < n; ++j) body.read(p.type, e.name.c_str());
      }
  }
};

}  // namespace

TriangleMesh readPly(const std::string& path) {
  const std::string data = slurp(path);
  if (data.compare(0, 3, "ply") != 0 || data.size() < 4 || (data[3] != '\n' && data[3] != '\r'))
    throw InputError(path, "not a PLY file (missing 'ply' magic)");
  const Header header = readHeader(path, data);
  BodyParser parser(path, data, header);
  for (const Element& e : header.elements) {
    if (e.name == "vertex") parser.readVertices(e);
    else if (e.name == "face") parser.readFaces(e);
    else parser.skipElement(e);
  }
  if (!parser.have_vertices) throw InputError(path, "PLY has no vertex element");
  return std::move(parser.mesh);
}

void writePly(const std::string& path, const TriangleMesh& mesh) {
  const std::size_t nv = mesh.vertices.size();
  const bool normals = !mesh.normals.empty();
  const bool colors = !mesh.colors.empty();
  if (normals && mesh.normals.size() != nv) throw InputError(path, "mesh has a normal count different from its vertex count");
  if (colors && mesh.colors.size() != nv) throw InputError(path, "mesh has a colour count different from its vertex count");

  std::string out = "ply\nformat binary_little_endian 1.0\ncomment written by vofusion\n";
  out += "element vertex " + std::to_string(nv) + "\nproperty float x\nproperty float y\nproperty float z\n";
  if (normals) out += "property float nx\nproperty float ny\nproperty float nz\n";
  if (colors) out += "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  out += "element face " + std::to_string(mesh.faces.size()) + "\nproperty list uchar int vertex_indices\nend_header\n";

  static_assert(sizeof(float) == 4, "PLY float is 32 bit");
  const auto put = [&out](const void* p, std::size_t n) { out.append(static_cast<const char*>(p), n); };
  const std::size_t header = out.size();
  out.reserve(header + nv * (12 + (normals ? 12 : 0) + (colors ? 3 : 0)) + mesh.faces.size() * 13);
  // Little-endian hosts only (x86/ARM): the bytes of float/int32 go out as they are in memory.
  for (std::size_t i = 0; i < nv; ++i) {
    put(mesh.vertices[i].data(), 12);
    if (normals) put(mesh.normals[i].data(), 12);
    if (colors) put(mesh.colors[i].data(), 3);
  }
  for (const auto& f : mesh.faces) {
    const std::uint8_t three = 3;
    put(&three, 1);
    for (std::uint32_t idx : f) {
      if (idx >= nv) throw InputError(path, "mesh face references vertex " + std::to_string(idx) + " out of range");
      const std::int32_t i32 = static_cast<std::int32_t>(idx);
      put(&i32, 4);
    }
  }
  writeFileAtomically(path, out);
}

}  // namespace vofusion
