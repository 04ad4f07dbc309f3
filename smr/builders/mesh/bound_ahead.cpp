// Collapse bounds computed ahead on helper threads (bound_ahead.h); the order of the collapses,
// Garland & Heckbert 1997's greedy order in bands, does not depend on them.
#include "smr/builders/mesh/bound_ahead.h"

#include <algorithm>

namespace smr::qem {
namespace {

constexpr std::size_t kAheadHeld = std::size_t{1} << 14;  // jobs kept, about

// Jobs whose candidates changed are given back now and then: when twice as many are held as
// after the last time; past kAheadHeld, those finished are given back whatever their
// candidates (a result dropped is only computed again), so the jobs' memory stays small.
void give_back(AheadState& a, const PmMesh& m, const Candidates& c) {
  if (a.held.size() <= std::max<std::size_t>(16 * kAhead, 2 * a.kept)) return;
  const bool all = a.held.size() > kAheadHeld;
  std::erase_if(a.held, [&](std::uint32_t v) {
    AheadThreads::Job* job = a.job[v];
    if (job == nullptr) {  // used (bound_ahead)
      a.listed[v] = 0;
      return true;
    }
    if (!a.threads->done(*job)) return false;
    if (!all && !m.removed[v] && job->c.stamp == c.stamp[v]) return false;
    a.threads->release(*job);
    a.job[v] = nullptr;
    a.seen[v] = 0;
    a.listed[v] = 0;
    return true;
  });
  a.kept = a.held.size();
}

// Hands the helpers candidates that come up soon (not `skip`, nor those looked at already):
// from the front of the queue's heap order (not sorted: any order is right, this one is
// cheap), when fewer than kAhead / 2 wait for them. Items it is done with are flagged in the
// heap (Candidate::looked): a scan passed over about 127 items to post 1.5, each looked up in
// five per-vertex arrays (13 M look-ups on the bunny, half of this function's time).
void post_ahead(AheadState& a, const PmMesh& m, const CollapseLog& log, Candidates& c,
                QemPmStats& stats, double tolerance, const std::vector<Waited>& waited,
                std::uint32_t skip) {
  if (a.threads->queued() >= kAhead / 2) return;
  give_back(a, m, c);
  a.posting.clear();
  std::vector<Candidate>& items = c.heap.items();
  for (std::size_t i = 0; i < items.size() && i < 8 * kAhead && a.posting.size() < kAhead; ++i) {
    Candidate& cd = items[i];
    if (cd.looked || cd.from == skip) continue;
    if (m.removed[cd.from] || cd.stamp != c.stamp[cd.from] || m.removed[cd.to]) {
      cd.looked = true;  // stale for good
      continue;
    }
    if (waited[cd.from].error > tolerance) continue;
    AheadThreads::Job*& held = a.job[cd.from];
    if (a.seen[cd.from] == cd.stamp + 1 &&
        (held == nullptr || held->c.stamp != cd.stamp || held->tolerance == tolerance)) {
      cd.looked = true;  // handed over in this band
      continue;
    }
    if (held != nullptr && !a.threads->done(*held)) continue;  // a helper holds it
    cd.looked = true;
    a.seen[cd.from] = cd.stamp + 1;
    if (held != nullptr) a.threads->release(*held);
    if (!a.listed[cd.from]) {
      a.listed[cd.from] = 1;
      a.held.push_back(cd.from);
    }
    AheadThreads::Job& job = a.threads->make();
    job.error = nullptr;
    job.c = cd;
    job.tolerance = tolerance;
    snapshot(m, log, cd.from, cd.to, job.snap);
    held = &job;
    a.posting.push_back(&job);
  }
  a.threads->post(a.posting);
  stats.bounds_ahead += a.posting.size();
}

}  // namespace

AheadThreads::AheadThreads(unsigned helpers) {
  try {
    for (unsigned t = 0; t < helpers; ++t) threads_.emplace_back([this] { serve(); });
  } catch (...) {
    stop();  // the threads started so far
    throw;
  }
}

AheadThreads::Job& AheadThreads::make() {
  if (free_.empty()) {
    free_.push_back(&pool_.emplace_back());
  }
  Job& job = *free_.back();
  free_.pop_back();
  job.state.store(Job::kQueued, std::memory_order_relaxed);
  return job;
}

void AheadThreads::post(std::span<Job* const> jobs) {
  {
    std::lock_guard lock(mu_);
    queue_.insert(queue_.end(), jobs.begin(), jobs.end());
    queued_.store(queue_.size(), std::memory_order_relaxed);
  }
  work_cv_.notify_all();
}

void AheadThreads::wait(Job& job, BoundScratch& s) {
  {
    std::unique_lock lock(mu_);
    if (job.state.load(std::memory_order_relaxed) == Job::kQueued) {
      queue_.erase(std::find(queue_.begin(), queue_.end(), &job));
      queued_.store(queue_.size(), std::memory_order_relaxed);
      job.state.store(Job::kRunning, std::memory_order_relaxed);
    } else {
      waiting_ = true;
      done_cv_.wait(lock, [&] { return job.state.load() == Job::kDone; });
      waiting_ = false;
      return;
    }
  }
  try {
    run(job, s);
  } catch (...) {
    job.error = std::current_exception();  // rethrown by its user, as a helper's
  }
  job.state.store(Job::kDone);
}

void AheadThreads::stop() {
  {
    std::lock_guard lock(mu_);
    quit_ = true;
  }
  work_cv_.notify_all();
  for (std::thread& t : threads_) t.join();
}

void AheadThreads::run(Job& job, BoundScratch& s) {
  std::swap(s.snap, job.snap);
  const std::uint64_t computed = s.computed;
  job.error_bound = star_bound(job.tolerance, false, s).first;
  job.counted = s.computed != computed;
  s.computed = computed;  // counted when used (bound_ahead)
  job.new_e.assign(s.new_e.begin(), s.new_e.end());
  std::swap(s.snap, job.snap);
}

void AheadThreads::serve() {
  BoundScratch s;
  for (;;) {
    Job* job = nullptr;
    // A short spin first: sleeping and being woken for every few jobs cost more than them.
    for (int spin = 0; spin < 4000 && queued_.load(std::memory_order_relaxed) == 0; ++spin) {
      std::this_thread::yield();
    }
    {
      std::unique_lock lock(mu_);
      work_cv_.wait(lock, [&] { return quit_ || !queue_.empty(); });
      if (quit_) return;
      job = queue_.front();
      queue_.pop_front();
      queued_.store(queue_.size(), std::memory_order_relaxed);
      job->state.store(Job::kRunning, std::memory_order_relaxed);
    }
    try {
      run(*job, s);
    } catch (...) {
      job->error = std::current_exception();
    }
    std::lock_guard lock(mu_);
    job->state.store(Job::kDone);
    if (waiting_) done_cv_.notify_all();
  }
}

void start_ahead(AheadState& a, unsigned helpers, std::size_t n) {
  a.threads = std::make_unique<AheadThreads>(helpers);
  a.job.assign(n, nullptr);
  a.seen.assign(n, 0);
  a.listed.assign(n, 0);
}

double bound_ahead(AheadState& a, const PmMesh& m, const CollapseLog& log, Candidates& c,
                   BoundScratch& s, QemPmStats& stats, const Candidate& top, double tolerance,
                   const std::vector<Waited>& waited) {
  AheadThreads::Job* job = a.job[top.from];
  if (job == nullptr || job->c.to != top.to || job->c.stamp != top.stamp ||
      job->tolerance != tolerance) {
    post_ahead(a, m, log, c, stats, tolerance, waited, top.from);  // the helpers start meanwhile
    return bound_within(m, log, top.from, top.to, tolerance, false, s).first;
  }
  if (!a.threads->done(*job)) a.threads->wait(*job, s);
  if (job->error) std::rethrow_exception(job->error);
  if (job->counted) ++s.computed;
  s.new_e.assign(job->new_e.begin(), job->new_e.end());
  const double error = job->error_bound;
  // Used: given back (the candidate is out of the queue; if it comes back, in a later band,
  // it may be handed over again).
  a.threads->release(*job);
  a.job[top.from] = nullptr;
  a.seen[top.from] = 0;
  ++stats.bounds_ahead_used;
  post_ahead(a, m, log, c, stats, tolerance, waited, top.from);
  return error;
}

}  // namespace smr::qem
