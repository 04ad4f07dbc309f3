// The session table of smrdb serve (sessions.h).
#include "tools/serve/sessions.h"

#include <cstdio>
#include <random>

namespace smr::serve {

void SessionTable::expire(std::chrono::steady_clock::time_point now) {
  for (auto it = entries_.begin(); it != entries_.end();) {
    if (now - it->second->last_used > idle_)
      it = entries_.erase(it);  // a request still updating it keeps its shared_ptr
    else
      ++it;
  }
}

std::shared_ptr<SessionEntry> SessionTable::create(const std::string& db,
                                                   std::unique_ptr<Session> session,
                                                   std::string& id) {
  static thread_local std::mt19937_64 rng{std::random_device{}()};
  const auto now = std::chrono::steady_clock::now();
  std::lock_guard lock(mutex_);
  expire(now);
  if (entries_.size() >= max_) return nullptr;
  char text[40];
  std::snprintf(text, sizeof text, "%016llx%016llx", static_cast<unsigned long long>(rng()),
                static_cast<unsigned long long>(rng() ^ ++counter_));
  id = text;
  auto entry = std::make_shared<SessionEntry>();
  entry->db = db;
  entry->session = std::move(session);
  entry->last_used = now;
  entries_[id] = entry;
  return entry;
}

std::shared_ptr<SessionEntry> SessionTable::find(const std::string& db, const std::string& id) {
  const auto now = std::chrono::steady_clock::now();
  std::lock_guard lock(mutex_);
  expire(now);
  const auto it = entries_.find(id);
  if (it == entries_.end() || it->second->db != db) return nullptr;
  it->second->last_used = now;
  return it->second;
}

bool SessionTable::remove(const std::string& db, const std::string& id) {
  std::lock_guard lock(mutex_);
  const auto it = entries_.find(id);
  if (it == entries_.end() || it->second->db != db) return false;
  entries_.erase(it);
  return true;
}

std::size_t SessionTable::size() {
  std::lock_guard lock(mutex_);
  expire(std::chrono::steady_clock::now());
  return entries_.size();
}

}  // namespace smr::serve
