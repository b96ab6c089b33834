#pragma once
// Reading a file a user or a client names, without ever blocking on it: a FIFO, a device or a directory given
// where a YAML file belongs is refused by type before a byte is read (issue 16, defect 5: a FIFO named as a
// job's `spec` blocked a daemon thread and later its shutdown).
#include <cstddef>
#include <filesystem>
#include <string>

namespace scancell {

/// What kind of file system object `path` is ("regular file", "FIFO", "directory", ...), following links;
/// "missing" when it does not exist.
std::string file_kind(const std::filesystem::path& path);

/// The whole of a regular file of at most `max_bytes`. Opened non-blocking and checked on the open descriptor
/// (no window between the check and the read). Throws ConfigError naming the file and why.
std::string read_regular_file(const std::filesystem::path& path, std::size_t max_bytes);

}  // namespace scancell
