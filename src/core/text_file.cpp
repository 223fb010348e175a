#include "vofusion/core/text_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <system_error>

#include "vofusion/core/errors.h"

namespace vofusion {

std::string readTextFile(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) throw InputError(path, "is a folder, expected a file");
  // An hour's ground truth at 100 Hz is ~25 MiB (TUM's longest lists are under 5 MiB). A larger file is
  // another kind (a rawlog given where a list goes), refused before it is read, copied and split.
  constexpr std::uintmax_t kMaxBytes = std::uintmax_t(256) << 20;
  if (const auto size = std::filesystem::file_size(path, ec); !ec && size > kMaxBytes)
    throw InputError(path, "is " + std::to_string(size >> 20) + " MiB: too large for a text file here (256 MiB at most)");
  std::ifstream f(path, std::ios::binary);
  if (!f) throw InputError(path, std::string("cannot open file (") + std::strerror(errno) + ")");
  // The read itself is capped too: a pipe or a device (/dev/zero) has no size to check first.
  return readCapped(f, path, kMaxBytes, "256 MiB", "a text file");
}

std::FILE* openRegularFile(const std::string& path, std::string* why) {
  const auto fail = [&](std::string reason) -> std::FILE* {
    if (why) *why = std::move(reason);
    return nullptr;
  };
  // O_NONBLOCK: a FIFO opens at once instead of waiting for a writer; a regular file reads as usual.
  const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) return fail(std::generic_category().message(errno));  // strerror is not for reader threads
  struct stat st {};
  const bool stated = ::fstat(fd, &st) == 0;
  const int stat_errno = errno;
  if (!stated || !S_ISREG(st.st_mode)) {
    ::close(fd);
    if (!stated) return fail(std::generic_category().message(stat_errno));
    return fail(S_ISDIR(st.st_mode) ? "a folder, not a file" : "not a regular file (a FIFO or a device?)");
  }
  std::FILE* f = ::fdopen(fd, "rb");
  if (!f) {
    const int open_errno = errno;
    ::close(fd);
    return fail(std::generic_category().message(open_errno));
  }
  if (why) why->clear();
  return f;
}

std::string whyUnreadable(const std::string& path) {
  std::string why;
  if (std::FILE* f = openRegularFile(path, &why)) std::fclose(f);
  return why;
}

bool entryExists(const std::string& path) {
  std::error_code ec;
  return std::filesystem::exists(std::filesystem::symlink_status(path, ec));
}

std::string readCapped(std::istream& stream, const std::string& path, std::size_t max_bytes, const std::string& what,
                       const std::string& kind) {
  std::string data;
  std::array<char, 1 << 16> buf;
  while (stream.read(buf.data(), buf.size()) || stream.gcount() > 0) {
    data.append(buf.data(), std::size_t(stream.gcount()));
    if (data.size() > max_bytes) throw InputError(path, "goes on past " + what + ": too large for " + kind + " here");
  }
  if (stream.bad()) throw InputError(path, "cannot read file");
  return data;
}

std::vector<TextLine> dataLines(const std::string& text) {
  std::vector<TextLine> lines;
  // A UTF-8 byte order mark (an editor's, e.g. Notepad's) is no part of the first line, as the config
  // reader takes it; it made a header comment line 1's data.
  std::istringstream in(text.rfind("\xEF\xBB\xBF", 0) == 0 ? text.substr(3) : text);
  // Lines ended by CR alone (classic Mac OS editors) were one comment line: the list held no frames.
  const char end = text.find('\n') == std::string::npos && text.find('\r') != std::string::npos ? '\r' : '\n';
  std::string line;
  for (int n = 1; std::getline(in, line, end); ++n) {
    const auto first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') continue;
    lines.push_back({n, std::move(line)});
  }
  return lines;
}

std::string fileStamp(const std::string& path) {
  std::error_code ec;
  const auto size = std::filesystem::file_size(path, ec);
  if (ec) return "";
  const auto time = std::filesystem::last_write_time(path, ec);
  if (ec) return "";
  return std::to_string(size) + " bytes, written " + std::to_string(time.time_since_epoch().count());
}

}  // namespace vofusion
