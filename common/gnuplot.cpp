#include "common/gnuplot.hpp"

#include <pthread.h>
#include <sys/wait.h>
#include <unistd.h>

#include <csignal>
#include <cstdio>
#include <stdexcept>
#include <vector>

namespace scancell {

namespace fs = std::filesystem;

ScratchDir::ScratchDir(const std::string& prefix) {
  std::string tmpl = (fs::temp_directory_path() / (prefix + "-XXXXXX")).string();
  std::vector<char> buf(tmpl.begin(), tmpl.end());
  buf.push_back('\0');
  if (!::mkdtemp(buf.data())) throw std::runtime_error("cannot create a temporary directory for " + prefix);
  path = buf.data();
}

ScratchDir::~ScratchDir() {
  std::error_code ec;
  fs::remove_all(path, ec);
}

std::string gnuplot_quoted(const std::string& s) {
  if (s.find('\n') != std::string::npos) throw std::runtime_error("a gnuplot file name cannot hold a line break: " + s);
  std::string out = "'";
  for (const char c : s) out += c == '\'' ? std::string("''") : std::string(1, c);
  return out + "'";
}

std::string gnuplot_text(const std::string& s) {
  std::string out = "\"";
  for (const char c : s) {
    if (c == '\\' || c == '"') out += '\\', out += c;
    else if (c == '\n') out += "\\n";
    else out += c;
  }
  return out + "\"";
}

void run_gnuplot(const std::string& terminal, const std::string& script, const fs::path& png, const std::string& what) {
  const fs::path tmp = png.string() + ".tmp";
  const std::string full =
      "set terminal " + terminal + "\nset output " + gnuplot_quoted(tmp.string()) + "\n" + script + "\nunset output\n";
  // A gnuplot that is missing or dies early closes the pipe: the write must fail with EPIPE, not raise
  // SIGPIPE and end the process (a daemon drawing a job's pictures). SIGPIPE is blocked on this thread while
  // writing, and one it raised is taken off the thread's pending set before the mask is restored.
  sigset_t pipe_only, old_mask;
  sigemptyset(&pipe_only);
  sigaddset(&pipe_only, SIGPIPE);
  pthread_sigmask(SIG_BLOCK, &pipe_only, &old_mask);
  FILE* gp = ::popen("gnuplot 2>&1", "w");
  if (!gp) {
    pthread_sigmask(SIG_SETMASK, &old_mask, nullptr);
    throw std::runtime_error(what + ": cannot start gnuplot");
  }
  std::fwrite(full.data(), 1, full.size(), gp);
  const int st = ::pclose(gp);
  sigset_t pending;
  sigpending(&pending);
  if (sigismember(&pending, SIGPIPE)) {
    const timespec zero{0, 0};
    sigtimedwait(&pipe_only, nullptr, &zero);
  }
  pthread_sigmask(SIG_SETMASK, &old_mask, nullptr);
  if (!WIFEXITED(st) || WEXITSTATUS(st) == 127)
    throw std::runtime_error(what + " needs gnuplot on the PATH (Debian: gnuplot-nox; scripts/deps.sh installs it)");
  std::error_code ec;
  if (WEXITSTATUS(st) != 0 || !fs::exists(tmp, ec) || fs::file_size(tmp, ec) == 0) {
    fs::remove(tmp, ec);
    throw std::runtime_error(what + ": gnuplot failed (exit " + std::to_string(WEXITSTATUS(st)) + ") drawing " + png.string());
  }
  fs::rename(tmp, png);
}

}  // namespace scancell
