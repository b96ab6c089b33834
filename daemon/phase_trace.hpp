#pragma once
// Where the running job is, appended to a file one line per change (jobs.phase_trace_file): planning, moving,
// scanning, registering, storing, stored, verifying. One write(2) per line on an O_APPEND descriptor, so the
// line survives a kill -9 of the daemon (it is in the kernel's page cache): the crash tests read the last line
// to know where each kill landed, and an integrator can read where a daemon that died was.
#include <filesystem>
#include <string>

namespace scancell::daemon {

class PhaseTrace {
 public:
  /// No file: mark() does nothing.
  explicit PhaseTrace(const std::filesystem::path& file);
  ~PhaseTrace();
  PhaseTrace(const PhaseTrace&) = delete;
  PhaseTrace& operator=(const PhaseTrace&) = delete;
  void mark(const std::string& phase) const;

 private:
  int fd_ = -1;
};

}  // namespace scancell::daemon
