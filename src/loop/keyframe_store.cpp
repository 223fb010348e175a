#include "vofusion/loop/keyframe_store.h"

#include <cstring>
#include <limits>
#include <stdexcept>

#include "vofusion/core/deflate.h"
#include "vofusion/core/errors.h"

namespace vofusion::loop {

namespace {
// Little helpers over a byte vector (same machine, same run: native byte order).
template <class T>
void put(std::vector<std::uint8_t>& out, const T& v) {
  const auto* p = reinterpret_cast<const std::uint8_t*>(&v);
  out.insert(out.end(), p, p + sizeof(T));
}
void putBytes(std::vector<std::uint8_t>& out, const void* data, std::size_t n) {
  const auto* p = static_cast<const std::uint8_t*>(data);
  out.insert(out.end(), p, p + n);
}

struct Reader {
  const std::vector<std::uint8_t>& in;
  std::size_t at = 0;
  const std::uint8_t* take(std::size_t n) {
    if (n > in.size() - at) throw std::runtime_error("corrupt record in the keyframes' spill file");
    const std::uint8_t* p = in.data() + at;
    at += n;
    return p;
  }
  template <class T>
  T get() {
    T v;
    std::memcpy(&v, take(sizeof(T)), sizeof(T));
    return v;
  }
};

std::size_t dataBytes(const Keyframe& k) {
  std::size_t n = k.depth.total() * k.depth.elemSize();
  if (k.features) n += k.features->descriptors.total() * k.features->descriptors.elemSize() + k.features->points.size() * sizeof(Eigen::Vector3d);
  return n;
}

// A spilled record is the encoded keyframe and a CRC-32 of it: zlib's check covers the depth only, and
// damaged descriptors or points would read back as another keyframe's features.
void seal(std::vector<std::uint8_t>& bytes) {
  const std::uint32_t crc = crc32(bytes.data(), bytes.size());
  putBytes(bytes, &crc, sizeof crc);
}
// The encoded keyframe back (the CRC taken off); false when the CRC does not hold.
bool unseal(std::vector<std::uint8_t>& bytes) {
  std::uint32_t crc = 0;
  if (bytes.size() < sizeof crc) return false;
  std::memcpy(&crc, bytes.data() + bytes.size() - sizeof crc, sizeof crc);
  bytes.resize(bytes.size() - sizeof crc);
  return crc == crc32(bytes.data(), bytes.size());
}
}  // namespace

std::vector<std::uint8_t> encodeKeyframeData(const Keyframe& k) {
  std::vector<std::uint8_t> out;
  const cv::Mat depth = k.depth.isContinuous() ? k.depth : k.depth.clone();
  const std::vector<std::uint8_t> z = zlibCompress(depth.data, depth.total() * depth.elemSize());
  put<std::int32_t>(out, depth.rows);
  put<std::int32_t>(out, depth.cols);
  put<std::uint64_t>(out, z.size());
  putBytes(out, z.data(), z.size());
  put<std::uint8_t>(out, k.features ? 1 : 0);
  if (k.features) {
    const cv::Mat d = k.features->descriptors.isContinuous() ? k.features->descriptors : k.features->descriptors.clone();
    put<std::int32_t>(out, d.rows);
    put<std::int32_t>(out, d.cols);
    put<std::int32_t>(out, d.type());
    putBytes(out, d.data, d.total() * d.elemSize());
    put<std::uint64_t>(out, k.features->points.size());
    putBytes(out, k.features->points.data(), k.features->points.size() * sizeof(Eigen::Vector3d));
  }
  return out;
}

void decodeKeyframeData(const std::vector<std::uint8_t>& bytes, Keyframe& k) {
  Reader r{bytes};
  const auto rows = r.get<std::int32_t>(), cols = r.get<std::int32_t>();
  const auto zlen = r.get<std::uint64_t>();
  const std::uint8_t* z = r.take(zlen);
  // zlib inflates at most ~1032 bytes a byte: a size beyond that is damage, before it sizes a buffer.
  if (rows < 0 || cols < 0 || std::uint64_t(rows) * std::uint64_t(cols) * 2 > zlen * 1032 + 1024)
    throw std::runtime_error("corrupt record in the keyframes' spill file");
  k.depth.create(rows, cols, CV_16U);
  if (!zlibUncompress(z, zlen, k.depth.data, k.depth.total() * k.depth.elemSize()))
    throw std::runtime_error("corrupt depth in the keyframes' spill file");
  k.features.reset();
  if (r.get<std::uint8_t>() == 0) return;
  auto f = std::make_shared<DescribedKeypoints>();
  const auto drows = r.get<std::int32_t>(), dcols = r.get<std::int32_t>(), dtype = r.get<std::int32_t>();
  // 32 bytes a row, as the place index and the matcher read them (another width ended the loop thread).
  if (drows < 0 || (drows > 0 && dcols != 32) || dcols < 0 || dtype != CV_8U ||
      std::uint64_t(drows) * std::uint64_t(dcols) > bytes.size())
    throw std::runtime_error("corrupt descriptors in the keyframes' spill file");
  f->descriptors.create(drows, dcols, dtype);
  std::memcpy(f->descriptors.data, r.take(f->descriptors.total()), f->descriptors.total());
  const auto npoints = r.get<std::uint64_t>();
  // A point for each descriptor (matching reads points[descriptor row]; zlib's check covers the depth
  // only), and no more than the record holds (before they size a buffer).
  if (npoints != std::uint64_t(drows) || npoints > bytes.size() / sizeof(Eigen::Vector3d))
    throw std::runtime_error("corrupt points in the keyframes' spill file");
  f->points.resize(npoints);
  // Three doubles each, no padding (Eigen::Vector3d is not vectorised): the bytes encode wrote.
  static_assert(sizeof(Eigen::Vector3d) == 3 * sizeof(double));
  std::memcpy(static_cast<void*>(f->points.data()), r.take(npoints * sizeof(Eigen::Vector3d)), npoints * sizeof(Eigen::Vector3d));
  if (r.at != bytes.size()) throw std::runtime_error("corrupt record in the keyframes' spill file (bytes past its end)");
  k.features = std::move(f);
}

KeyframeStore::KeyframeStore(std::size_t cache_bytes, std::string spill_dir)
    : cache_bytes_(cache_bytes), spill_(std::move(spill_dir), "the keyframes' spill file") {}

void KeyframeStore::add(Keyframe k) {
  ram_bytes_ += dataBytes(k);
  keyframes_.push_back(std::move(k));
  // The newest keyframe always stays (it is about to be matched); older ones leave oldest first.
  while (ram_bytes_ > cache_bytes_ && spilled_ + 1 < keyframes_.size()) {
    Keyframe& old = keyframes_[spilled_];
    std::vector<std::uint8_t> bytes = encodeKeyframeData(old);
    seal(bytes);
    const std::optional<SpillFile::Record> record = spill_.append(bytes);
    if (!record) {
      // The spill file cannot be written (disk full; SpillFile warns): every keyframe stays in RAM
      // from now on, beyond the budget, and loops are still found among them all.
      cache_bytes_ = std::numeric_limits<std::size_t>::max();
      return;
    }
    records_.push_back(*record);
    ++spilled_;
    ram_bytes_ -= dataBytes(old);
    old.features.reset();
    old.depth.release();
  }
}

bool KeyframeStore::readBack(std::size_t id, std::vector<std::uint8_t>& bytes, Keyframe& k) const {
  std::string why = "damaged record";
  try {
    bytes = spill_.read(records_[id]);
    if (unseal(bytes)) {
      decodeKeyframeData(bytes, k);
      return true;
    }
  } catch (const SpillFile::ReadError& e) {  // pread failed, or the file is short (not memory)
    why = e.cause;
  } catch (const std::runtime_error& e) {  // decoding refused it (a CRC that held over damage)
    why = e.what();
  } catch (const cv::Exception& e) {  // OpenCV could not make the depth image it states
    why = oneLineMessage(e);
  }
  k.features.reset();
  k.depth.release();
  spill_.lost(id, spill_.folder() + ": cannot read a keyframe back from the keyframes' spill file (" + why +
                      "): such keyframes close no loop any more (summary.json: loop_closure.keyframes_lost), the run goes on");
  return false;
}

Keyframe KeyframeStore::load(std::size_t id) const {
  Keyframe k = keyframes_.at(id);
  if (id >= spilled_) return k;
  std::vector<std::uint8_t> bytes;
  if (readBack(id, bytes, k)) reloaded_.fetch_add(1, std::memory_order_relaxed);
  return k;
}

std::vector<std::uint8_t> KeyframeStore::data(std::size_t id) const {
  if (id >= spilled_) return encodeKeyframeData(keyframes_.at(id));
  // Spilled as encodeKeyframeData made it, decoded once to check it (not compressed again): damage is
  // found now, not sealed into a checkpoint that fails only when resumed.
  std::vector<std::uint8_t> bytes;
  Keyframe check;
  if (readBack(id, bytes, check)) return bytes;
  return encodeKeyframeData(check);  // lost: no features, no depth
}

KeyframeStoreStats KeyframeStore::stats() const {
  KeyframeStoreStats s;
  s.keyframes = keyframes_.size();
  s.in_ram = keyframes_.size() - spilled_;
  s.spilled = spilled_;
  s.reloaded = reloaded_.load(std::memory_order_relaxed);
  s.lost = spill_.lostCount();
  s.spill_file_bytes = spill_.bytes();
  s.spill_error = spill_.failure();
  return s;
}

}  // namespace vofusion::loop
