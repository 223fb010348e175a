#pragma once
// Small text inputs (TUM lists and trajectories, intrinsics.txt): whole-file reads and the data lines
// of a '#'-commented format, with line numbers for error messages.
#include <cstddef>
#include <cstdio>
#include <istream>
#include <string>
#include <vector>

namespace vofusion {

// The whole file; throws InputError(path, ...) when it cannot be opened or is over 256 MiB.
std::string readTextFile(const std::string& path);
// Whether there is an entry at `path`, whatever it leads to: a link to nowhere or to itself is there,
// and its reader names the problem in one line (std::filesystem::exists threw on a link to itself,
// and the run ended with its error). Never throws.
bool entryExists(const std::string& path);
// A file as it is now: its size and last write time as text ("N bytes, written T"; "" when it cannot be
// stat'ed), to tell whether it was replaced since (a saved map a run went on from, a rendered recording).
std::string fileStamp(const std::string& path);
// `path` opened for reading ("rb") if it is a regular file, else nullptr with `why` (when given) set:
// the system's words ("Permission denied", "No such file or directory"), "a folder, not a file" or
// "not a regular file (a FIFO or a device?)". Opened without waiting, then judged by what was opened:
// a FIFO is never waited on (fopen waits for a writer, for ever), and nothing can be swapped in between
// a check and the open. The caller closes the file. Never throws.
std::FILE* openRegularFile(const std::string& path, std::string* why = nullptr);
// Why the file at `path` cannot be opened for reading (openRegularFile's `why`); empty when it can. A
// reader that fails on a file names this cause first, rather than calling an unreadable file corrupt.
// Never throws.
std::string whyUnreadable(const std::string& path);
// Everything `stream` gives, read in 64 KiB pieces; InputError(path, "goes on past <what>: too large
// for <kind> here") once it is longer than max_bytes (a pipe or a device has no size to check first).
std::string readCapped(std::istream& stream, const std::string& path, std::size_t max_bytes, const std::string& what,
                       const std::string& kind);

struct TextLine {
  int number = 0;    // 1-based line number in the text
  std::string text;  // the line as written (may end with '\r')
};
// The lines that are neither blank nor comments (first non-blank character '#'); lines end at LF, or at
// CR in a file that has no LF (classic Mac OS).
std::vector<TextLine> dataLines(const std::string& text);

}  // namespace vofusion
