#include "tools/rss.h"

#include <malloc.h>
#include <sys/resource.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>

namespace smr::tools {

namespace {
// The process's peak resident set before the last reset_peak_rss() (MiB).
double g_peak_before_reset_mb = 0.0;
}  // namespace

double peak_rss_mb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);  // ru_maxrss: kilobytes on Linux
  return std::max(g_peak_before_reset_mb, double(u.ru_maxrss) / 1024.0);
}

bool reset_peak_rss() {
  g_peak_before_reset_mb = peak_rss_mb();
  malloc_trim(0);  // the phase before may have freed much that glibc still holds
  std::FILE* f = std::fopen("/proc/self/clear_refs", "w");
  if (f == nullptr) return false;
  const bool ok = std::fputs("5", f) >= 0;
  return std::fclose(f) == 0 && ok;
}

double phase_peak_rss_mb() {
  std::FILE* f = std::fopen("/proc/self/status", "r");
  if (f == nullptr) return 0.0;
  char line[256];
  double kb = 0.0;
  while (std::fgets(line, sizeof line, f) != nullptr) {
    if (std::strncmp(line, "VmHWM:", 6) == 0) kb = std::strtod(line + 6, nullptr);
  }
  std::fclose(f);
  return kb / 1024.0;
}

}  // namespace smr::tools
