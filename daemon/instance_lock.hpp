#pragma once
// One daemon per data directory and per control socket (issue 16, defect 6): a second scancelld on the same
// data directory used to take over the socket, home the drives under a running sweep and execute the same job.
// An exclusive flock(2) on DATA_DIR/scancelld.lock and on SOCKET.lock, held for the daemon's life (the kernel
// drops it when the process dies, kill -9 included); the holder's PID is written into the file so that the
// refusal can name it.
#include <filesystem>

namespace scancell::daemon {

class InstanceLock {
 public:
  /// Throws std::runtime_error naming the file and the PID holding it when another process has it.
  explicit InstanceLock(const std::filesystem::path& file);
  ~InstanceLock();
  InstanceLock(const InstanceLock&) = delete;
  InstanceLock& operator=(const InstanceLock&) = delete;

 private:
  int fd_ = -1;
};

}  // namespace scancell::daemon
