#pragma once
// A rawlog's external files (images in "<name>_Images/") without MRPT's process-wide images folder.
//
// MRPT resolves every relative external file name (CImage::setExternalStorage, a range image's .bin)
// against one global folder (CImage::setImagesPathBase), and CObservation3DRangeScan::
// rangeImage_convertToExternalStorage swaps that folder while it writes. With a reader, a prefetch
// thread and a writer in one process, each resolved the others' files (issue 34: one run in five read
// an image from its own output's folder). These functions never read or change that folder:
// - a record read gets absolute file names (resolveExternalFiles), so loading it reads no global;
// - a record written keeps MRPT's relative names (the rawlog stays relocatable) but its range image is
//   written here, into an explicit folder (writeRangeImageExternally).
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <mrpt/obs/CObservation3DRangeScan.h>

#include "vofusion/core/frame.h"

namespace vofusion {

// Every relative external file of `obs` (intensity, confidence, range image, 3D points) becomes
// images_dir/<name>, with images_dir made absolute: obs.load() and the images' pixels then read no
// global state. Absolute names are kept as they are.
void resolveExternalFiles(mrpt::obs::CObservation3DRangeScan& obs, const std::string& images_dir);

// When obs's range image is stored externally (named absolutely: resolveExternalFiles), reads it into
// obs.rangeImage, checked whole, and the observation no longer refers to the file. MRPT's load() reads
// such a file unchecked: one cut short or with flipped bits gave a frame of wrong depths, used as it
// came. Throws InputError(file, ...) when it is missing, empty, cut short or damaged (its gzip CRC-32).
// A file of another kind (a .txt, a plain binary one, a gzip of older rawlogs' float layout) is left
// for MRPT's load(). Returns the file read here (none when there was none, or it was left to MRPT).
std::optional<DepthFile> loadExternalRangeImage(mrpt::obs::CObservation3DRangeScan& obs);
// Puts a frame's range-image file at `path` instead of writing its depth again, when the file holds
// readings in `units` and still is the file it was (its size and gzip trailer): a hard link to our own
// recording's file, a copy of another's. Returns the file at `path` (not recorded), or none, having
// written nothing. Throws InputError(shown, ...) when a copy cannot be written.
std::optional<DepthFile> reuseRangeImageFile(const DepthFile& file, double units, const std::string& path,
                                             const std::string& shown);
// The same for a frame's colour PNG: our recording's file is linked; another's is copied when it is an
// 8-bit RGB PNG of width x height (so it decodes to the frame's pixels). False: nothing written.
bool reuseColourFile(const ColourFile& file, int width, int height, const std::string& path, const std::string& shown);

// Writes obs.rangeImage to dir/file_name in MRPT's external format (gzip: rows, cols as uint32, then
// the uint16 ranges, little-endian) and marks it externally stored under the relative file_name,
// releasing the matrix. What rangeImage_convertToExternalStorage(file_name, dir) writes, without its
// global. Returns the file written (not recorded). Throws InputError(shown, ...) when it cannot be
// written: `shown` names the file as the user will find it (dir/file_name when empty; a writer's
// temporary folder is gone by the time the message is read).
DepthFile writeRangeImageExternally(mrpt::obs::CObservation3DRangeScan& obs, const std::string& file_name,
                                    const std::string& dir, const std::string& shown = "");
// Writes `bytes` to `path`, or removes what it wrote and throws InputError(shown, "cannot write <what>:
// <why>"): no half-written image is left. `shown` names the file as the user will find it.
void writeExternalFile(const std::string& path, const std::vector<std::uint8_t>& bytes, const std::string& shown,
                       const std::string& what);
// Marks obs's range image externally stored under the relative file_name, a file that already holds
// it (reuseRangeImageFile's), releasing the matrix.
void useExternalRangeImage(mrpt::obs::CObservation3DRangeScan& obs, const std::string& file_name);

}  // namespace vofusion
