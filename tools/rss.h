// The process's resident set, as `--json` reports it (Linux: getrusage, /proc/self/status).
#pragma once

namespace smr::tools {

/// The process's peak resident set so far, in MiB (across reset_peak_rss() calls).
double peak_rss_mb();

/// Starts measuring a phase's own peak resident set (Linux: clear_refs 5 resets VmHWM); false if
/// the kernel does not allow it. peak_rss_mb() still reports the whole run's peak.
bool reset_peak_rss();

/// The resident set's peak since reset_peak_rss() (VmHWM), in MiB; 0 if unknown.
double phase_peak_rss_mb();

}  // namespace smr::tools
