#include "common/worker_process.hpp"

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <stdexcept>
#include <vector>

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/mman.h>
#include <sys/prctl.h>
#include <unistd.h>

extern char** environ;

namespace scancell {
namespace {

constexpr const char* kKindVar = "SCANCELL_WORKER";
constexpr const char* kArgVar = "SCANCELL_WORKER_ARG";
constexpr const char* kParentVar = "SCANCELL_WORKER_PARENT";
constexpr int kOutFd = 3;  // the pipe's write end in the worker

[[noreturn]] void fail(const std::string& what) {
  throw std::runtime_error("cannot start a worker process: " + what + ": " + std::strerror(errno));
}

}  // namespace

bool run_if_worker(const char* kind, WorkerEntry entry) {
  const char* k = std::getenv(kKindVar);
  if (!k || std::strcmp(k, kind) != 0) return false;
  // Die with the caller: an orphaned worker on a looping file would spin for ever.
  ::prctl(PR_SET_PDEATHSIG, SIGKILL);
  const char* parent = std::getenv(kParentVar);
  if (!parent || std::strtol(parent, nullptr, 10) != static_cast<long>(::getppid())) ::_exit(125);
  const char* arg = std::getenv(kArgVar);
  int status = 124;
  try {
    status = entry(kOutFd, arg ? arg : "");
  } catch (...) {
  }
  ::_exit(status);  // no atexit handlers, no leak check: the answer is on the pipe
}

std::string read_worker_input() {
  std::string in;
  char buf[65536];
  while (true) {
    const ssize_t n = ::read(0, buf, sizeof buf);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    in.append(buf, static_cast<std::size_t>(n));
  }
  return in;
}

SpawnedWorker spawn_worker(const char* kind, const std::string& arg, const std::string& input) {
  if (arg.find('\0') != std::string::npos) throw std::invalid_argument("spawn_worker: the argument holds a NUL byte");
  // The input, whole, in an anonymous file the worker reads as stdin from its start.
  // Above fd 2 (a daemon may have closed its stdin), so the dup2 onto fd 0 clears close-on-exec.
  const int in0 = ::memfd_create("scancell-worker-input", MFD_CLOEXEC);
  if (in0 < 0) fail("memfd_create");
  const int in = ::fcntl(in0, F_DUPFD_CLOEXEC, 16);
  ::close(in0);
  if (in < 0) fail("fcntl");
  for (std::size_t done = 0; done < input.size();) {
    const ssize_t n = ::write(in, input.data() + done, input.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const int e = errno;
      ::close(in);
      errno = n < 0 ? e : ENOSPC;
      fail("writing its input");
    }
    done += static_cast<std::size_t>(n);
  }
  if (::lseek(in, 0, SEEK_SET) != 0) {
    ::close(in);
    fail("lseek");
  }
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0) {
    ::close(in);
    fail("pipe");
  }
  // The write end goes to fd 3 in the worker; keep the source above 3 so dup2 clears its close-on-exec flag.
  const int w = ::fcntl(fds[1], F_DUPFD_CLOEXEC, 16);
  ::close(fds[1]);
  if (w < 0) {
    ::close(fds[0]);
    ::close(in);
    fail("fcntl");
  }
  std::vector<std::string> env_text;
  for (char** e = environ; e && *e; ++e) {
    const std::string s(*e);
    if (s.rfind(std::string(kKindVar) + "=", 0) != 0 && s.rfind(std::string(kArgVar) + "=", 0) != 0 &&
        s.rfind(std::string(kParentVar) + "=", 0) != 0)
      env_text.push_back(s);
  }
  env_text.push_back(std::string(kKindVar) + "=" + kind);
  env_text.push_back(std::string(kArgVar) + "=" + arg);
  env_text.push_back(std::string(kParentVar) + "=" + std::to_string(::getpid()));
  std::vector<char*> envp;
  for (auto& s : env_text) envp.push_back(s.data());
  envp.push_back(nullptr);
  std::string self = "/proc/self/exe";
  std::string argv0 = std::string("scancell-") + kind;
  char* argv[] = {argv0.data(), nullptr};

  posix_spawn_file_actions_t fa;
  posix_spawnattr_t at;
  posix_spawn_file_actions_init(&fa);
  posix_spawnattr_init(&at);
  posix_spawn_file_actions_adddup2(&fa, in, 0);
  posix_spawn_file_actions_adddup2(&fa, w, kOutFd);
  posix_spawn_file_actions_addopen(&fa, 1, "/dev/null", O_WRONLY, 0);
  sigset_t none, all;
  sigemptyset(&none);
  sigfillset(&all);
  posix_spawnattr_setsigmask(&at, &none);
  posix_spawnattr_setsigdefault(&at, &all);
  posix_spawnattr_setflags(&at, POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF);
  pid_t pid = -1;
  const int rc = ::posix_spawn(&pid, self.c_str(), &fa, &at, argv, envp.data());
  posix_spawn_file_actions_destroy(&fa);
  posix_spawnattr_destroy(&at);
  ::close(w);
  ::close(in);
  if (rc != 0) {
    ::close(fds[0]);
    errno = rc;
    fail(self);
  }
  return {pid, fds[0]};
}

}  // namespace scancell
