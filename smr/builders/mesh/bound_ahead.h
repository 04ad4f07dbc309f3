// Collapse bounds computed ahead on helper threads for the in-core simplification's banded loop
// (qem_simplify.h). A collapse's bound (collapse_bound.h) depends only on the star of its removed
// vertex, the positions and the bounds of the collapses that made that star (StarSnapshot), none
// of which changes while the vertex's stamp stays. So the calling thread hands the helper threads
// snapshots of candidates that come up soon (those whose bound it would compute when they come
// up: current, not waiting; validity is left to the calling thread when they come up, as testing
// it here too cost that thread 4 % of the bunny's build and a helper computing a bound no one
// uses costs it nothing), kAhead at a time whenever fewer than kAhead / 2 wait, and goes on
// simplifying; a result is used if its candidate comes up with the same stamp and band; a bound
// not handed over, the calling thread computes itself, and one handed over but not started yet
// too. The simplification, and so the database, is the same whatever the number of threads.
// (Garland & Heckbert 1997's greedy order, section 4, is kept exactly: only the work moves.)
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <exception>
#include <memory>
#include <mutex>
#include <span>
#include <thread>
#include <vector>

#include "smr/builders/mesh/collapse_bound.h"
#include "smr/builders/mesh/qem_candidates.h"

namespace smr::qem {

// Per vertex, the bound its candidate last waited with: exact while its star and target are
// unchanged (stamp, to); after a change, a prediction that keeps it waiting without a new bound
// until the band reaches it (bounds only grow as a region coarsens; a wrong guess only delays
// the collapse, whose bound is computed before it is made).
struct Waited {
  std::uint32_t stamp = 0, to = kNone;
  double error = 0.0;
};

// The helper threads and the jobs handed to them.
class AheadThreads {
 public:
  // A candidate's bound: its snapshot, filled by the calling thread, and its result.
  struct Job {
    Candidate c{};
    double tolerance = 0.0;
    StarSnapshot snap;
    double error_bound = 0.0;
    bool counted = false;  // collapse_error ran (BoundScratch::computed)
    std::vector<double> new_e;
    std::exception_ptr error;  // what the computation threw, if it did
    enum State : int { kQueued, kRunning, kDone };
    std::atomic<int> state{kQueued};
  };

  explicit AheadThreads(unsigned helpers);
  ~AheadThreads() { stop(); }
  AheadThreads(const AheadThreads&) = delete;
  AheadThreads& operator=(const AheadThreads&) = delete;

  // The calling thread's: a job to fill (from the free ones), queueing it, and giving it back
  // once done with it (not while a helper may hold it: wait() first).
  Job& make();
  void post(std::span<Job* const> jobs);
  void release(Job& job) { free_.push_back(&job); }
  std::size_t queued() const { return queued_.load(std::memory_order_relaxed); }
  // Makes sure the job is done: run here if no helper has started it, else waited for.
  void wait(Job& job, BoundScratch& s);
  bool done(const Job& job) const { return job.state.load() == Job::kDone; }

 private:
  void stop();
  static void run(Job& job, BoundScratch& s);
  void serve();

  std::vector<std::thread> threads_;
  std::mutex mu_;
  std::condition_variable work_cv_, done_cv_;
  std::deque<Job*> queue_;  // jobs posted, not started
  bool quit_ = false;
  bool waiting_ = false;                // the calling thread waits for a job (wait())
  std::atomic<std::size_t> queued_{0};  // queue_.size(), read without the lock
  std::deque<Job> pool_;                // the calling thread's (stable addresses)
  std::vector<Job*> free_;              // the calling thread's
};

// The calling thread's side: the helpers and, per removed vertex, the job it holds.
struct AheadState {
  std::unique_ptr<AheadThreads> threads;
  std::vector<AheadThreads::Job*> job;  // per vertex: its job, if it holds one
  std::vector<std::uint32_t> seen;      // per vertex: 1 + the stamp post_ahead() last saw
  std::vector<std::uint32_t> held;      // the vertices that hold a job (or held one, used)
  std::vector<std::uint8_t> listed;     // per vertex: in `held`
  std::size_t kept = 0;                 // their number after post_ahead() last gave jobs back
  std::vector<AheadThreads::Job*> posting;
};

inline constexpr std::size_t kAhead = 16;  // candidates handed over at a time

/// `helpers` threads and the per-vertex tables for n vertices.
void start_ahead(AheadState& a, unsigned helpers, std::size_t n);

/// bound_within(top, tolerance, finish = false).first, with BoundScratch::new_e in s: the
/// helpers' result when they computed it for this candidate and band, else computed here (and
/// more candidates handed over).
double bound_ahead(AheadState& a, const PmMesh& m, const CollapseLog& log, Candidates& c,
                   BoundScratch& s, QemPmStats& stats, const Candidate& top, double tolerance,
                   const std::vector<Waited>& waited);

}  // namespace smr::qem
