#pragma once
// A file's own checksum at its end: the tag "CHECKSUM", the CRC-32 of every byte before it and their
// count (little-endian, 20 bytes). A flipped byte anywhere (a pose, a brick's coordinates, which no
// range check can tell from a right value) is found before the file is parsed.
#include <string>

namespace vofusion {

// Appends the trailer to the file written whole at `path`; false and why ("read back failed", "disk
// full?") when it could not.
bool appendFileChecksum(const std::string& path, std::string& why);
// Whether the file ends with a trailer that matches its bytes; false and why not.
bool fileChecksumHolds(const std::string& path, std::string& why);

}  // namespace vofusion
