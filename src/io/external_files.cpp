#include "vofusion/io/external_files.h"

#include <filesystem>

#include <mrpt/io/CFileGZOutputStream.h>
#include <mrpt/serialization/CArchive.h>

#include "vofusion/core/errors.h"

namespace fs = std::filesystem;
using mrpt::obs::CObservation3DRangeScan;

namespace vofusion {

namespace {
// The range image's and 3D points' file names are protected members with no setter but
// rangeImage_convertToExternalStorage (which swaps the global folder). A derived class may name them
// as pointers to members of the base, which is how they are reached here.
struct ExternalNames : CObservation3DRangeScan {
  static constexpr auto range_file = &ExternalNames::m_rangeImage_external_file;
  static constexpr auto range_stored = &ExternalNames::m_rangeImage_external_stored;
  static constexpr auto points_file = &ExternalNames::m_points3D_external_file;
  static constexpr auto points_stored = &ExternalNames::m_points3D_external_stored;
};

// MRPT's own test of an absolute name (mrpt::io::lazy_load_absolute_path).
bool isAbsolute(const std::string& f) {
  return !f.empty() && (f[0] == '/' || (f.size() > 2 && f[1] == ':' && (f[2] == '\\' || f[2] == '/')));
}

std::string resolved(const std::string& name, const fs::path& dir) {
  return isAbsolute(name) ? name : (dir / name).string();
}

void resolveImage(mrpt::img::CImage& img, const fs::path& dir) {
  if (img.isExternallyStored()) img.setExternalStorage(resolved(img.getExternalStorageFile(), dir));
}
}  // namespace

void resolveExternalFiles(CObservation3DRangeScan& obs, const std::string& images_dir) {
  const fs::path dir = fs::absolute(images_dir);
  resolveImage(obs.intensityImage, dir);
  resolveImage(obs.confidenceImage, dir);
  if (obs.*ExternalNames::range_stored) obs.*ExternalNames::range_file = resolved(obs.*ExternalNames::range_file, dir);
  if (obs.*ExternalNames::points_stored)
    obs.*ExternalNames::points_file = resolved(obs.*ExternalNames::points_file, dir);
}

void writeRangeImageExternally(CObservation3DRangeScan& obs, const std::string& file_name, const std::string& dir) {
  const std::string path = (fs::path(dir) / file_name).string();
  if (obs.rangeImage_isExternallyStored()) throw std::logic_error(path + ": range image is already external");
  try {
    mrpt::io::CFileGZOutputStream out;
    std::string err;
    if (!out.open(path, 1, err)) throw InputError(path, "cannot write range image: " + err);
    auto arch = mrpt::serialization::archiveFrom(out);
    const auto& ri = obs.rangeImage;
    arch.WriteAs<uint32_t>(ri.rows());
    arch.WriteAs<uint32_t>(ri.cols());
    if (ri.size() != 0) arch.WriteBufferFixEndianness<uint16_t>(ri.data(), ri.size());
    out.close();
  } catch (const InputError&) {
    throw;
  } catch (const std::exception&) {
    throw InputError(path, "cannot write range image (disk full?)");
  }
  obs.*ExternalNames::range_file = file_name;
  obs.*ExternalNames::range_stored = true;
  obs.rangeImage.setSize(0, 0);
}

}  // namespace vofusion
