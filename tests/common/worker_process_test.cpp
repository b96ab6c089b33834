// A worker is this executable started afresh (common/worker_process.hpp): it gets its argument and its whole
// input, answers on its pipe, and inherits no state of the caller, as a fork would (another thread's locks).
#include "common/worker_process.hpp"

#include <cerrno>
#include <string>

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

namespace scancell {
namespace {

int g_caller_state = 0;  // the caller sets it; a fresh process starts with 0

int echo_main(int out_fd, const std::string& arg) {
  const std::string out = arg + "|" + std::to_string(g_caller_state) + "|" + read_worker_input();
  for (std::size_t done = 0; done < out.size();) {
    const ssize_t n = ::write(out_fd, out.data() + done, out.size() - done);
    if (n <= 0) return 3;
    done += static_cast<std::size_t>(n);
  }
  return 7;
}
[[maybe_unused]] const bool echo_started = run_if_worker("test-echo", &echo_main);

/// The worker's whole answer and its exit status.
std::pair<std::string, int> run(const std::string& arg, const std::string& input) {
  const SpawnedWorker w = spawn_worker("test-echo", arg, input);
  std::string got;
  char buf[65536];
  for (ssize_t n; (n = ::read(w.read_fd, buf, sizeof buf)) != 0;) {
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) break;
    got.append(buf, static_cast<std::size_t>(n));
  }
  ::close(w.read_fd);
  int status = 0;
  while (::waitpid(w.pid, &status, 0) < 0 && errno == EINTR) {
  }
  return {got, WIFEXITED(status) ? WEXITSTATUS(status) : -WTERMSIG(status)};
}

TEST(WorkerProcess, AWorkerGetsItsArgumentAndWholeInputAndStartsFresh) {
  g_caller_state = 42;
  std::string input(3 * 1024 * 1024 + 17, '\0');  // larger than a pipe holds: the input is a file, not a pipe
  for (std::size_t i = 0; i < input.size(); ++i) input[i] = static_cast<char>(i * 131 % 251);
  const auto [answer, status] = run("a path with spaces/ünïcode.off", input);
  g_caller_state = 0;
  EXPECT_EQ(status, 7);
  // 0, not 42: a fresh image of this executable, not a copy of the caller's memory.
  EXPECT_EQ(answer, "a path with spaces/ünïcode.off|0|" + input);
}

TEST(WorkerProcess, AnEmptyInputIsAnEmptyStdin) {
  const auto [answer, status] = run("", "");
  EXPECT_EQ(status, 7);
  EXPECT_EQ(answer, "|0|");
}

TEST(WorkerProcess, AnArgumentWithANulByteIsRefused) {
  EXPECT_THROW(spawn_worker("test-echo", std::string("a\0b", 3)), std::invalid_argument);
}

}  // namespace
}  // namespace scancell
