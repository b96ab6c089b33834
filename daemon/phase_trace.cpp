#include "daemon/phase_trace.hpp"

#include <cerrno>
#include <cstring>
#include <stdexcept>

#include <fcntl.h>
#include <unistd.h>

namespace scancell::daemon {

PhaseTrace::PhaseTrace(const std::filesystem::path& file) {
  if (file.empty()) return;
  fd_ = ::open(file.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0640);
  if (fd_ < 0) throw std::runtime_error(file.string() + ": cannot open the phase trace: " + std::strerror(errno));
}

PhaseTrace::~PhaseTrace() {
  if (fd_ >= 0) ::close(fd_);
}

void PhaseTrace::mark(const std::string& phase) const {
  if (fd_ < 0) return;
  const std::string line = phase + "\n";
  (void)!::write(fd_, line.data(), line.size());  // best effort: a trace never stops a job
}

}  // namespace scancell::daemon
