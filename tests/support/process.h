// Running a program from the tests: to completion with its output captured, or spawned to be
// killed or measured.
#pragma once

#include <sys/types.h>

#include <string>
#include <vector>

namespace smr::test {

struct CommandResult {
  int code = -1;    // exit status, or -1 when killed by a signal
  std::string out;  // stdout and stderr together
};
/// Runs `command` through the shell (stderr joined to stdout).
CommandResult run_command(const std::string& command);

/// Starts argv[0] with `argv`, stdout to `stdout_path` (truncated; /dev/null by default) and
/// stderr to /dev/null. Returns its pid; throws std::runtime_error if it cannot start.
pid_t spawn(const std::vector<std::string>& argv, const std::string& stdout_path = "/dev/null");

struct Exit {
  int status = 0;        // as waitpid reports it
  long max_rss_kib = 0;  // the child's peak resident set (ru_maxrss)
};
/// Waits for `pid` (retrying on EINTR).
Exit wait_for(pid_t pid);
/// Waits up to `seconds` for `pid` to end, then kills it (SIGKILL) and waits for that: a kill at
/// a moment that does not sleep on after the process has ended by itself.
Exit kill_after(pid_t pid, double seconds);

}  // namespace smr::test
