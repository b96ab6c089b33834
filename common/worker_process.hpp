#pragma once
// Work that must not share the caller's process (an untrusted parser that may loop or crash) runs in a worker:
// this same executable started afresh (posix_spawn of /proc/self/exe), never a fork of the caller. A fork of a
// multithreaded process inherits every lock another thread held at that instant (the allocator's, a logger's,
// a TBB arena's) and may wait on it for ever: a mesh read hung 30 s this way in a clean-clone ASan CI.
//
// A worker kind is declared in the translation unit that does the work, at namespace scope:
//
//   const bool reader_started = run_if_worker("mesh-reader", &reader_main);
//
// In the worker that call runs `reader_main(out_fd, arg)` before main() and ends the process with its return
// value; in every other process it returns false at once. Only this TU's earlier statics and shared libraries
// are initialised by then, so the entry point must not rely on other translation units' globals.
#include <string>

#include <sys/types.h>

namespace scancell {

/// The worker's side: reads its input (if any) from stdin, writes its answer to `out_fd`, returns the exit status.
using WorkerEntry = int (*)(int out_fd, const std::string& arg);

/// Runs `entry` and _exits when this process was spawned as worker `kind`; returns false otherwise.
bool run_if_worker(const char* kind, WorkerEntry entry);

/// A running worker: its pid and the read end of the pipe it answers on (close it, then reap the pid).
struct SpawnedWorker {
  pid_t pid = -1;
  int read_fd = -1;
};

/// Starts this executable as worker `kind` with `arg` and `input` on its stdin (a sealed in-memory file, whole
/// before the worker starts, so neither side waits on the other). The worker's stdout goes to /dev/null
/// (stderr stays, so a sanitizer report reaches the log), its signal mask is empty, and it is killed if the
/// caller dies. Throws std::runtime_error naming the OS error when it cannot be started.
SpawnedWorker spawn_worker(const char* kind, const std::string& arg, const std::string& input = {});

/// The worker's side: all of stdin (the `input` above).
std::string read_worker_input();

}  // namespace scancell
