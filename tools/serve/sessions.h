// The progressive sessions of smrdb serve: a bounded table of smr::Session (Brown 6.3) with idle
// expiry. Each entry is updated by one request at a time (try_lock: a second one is a 409).
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <unordered_map>

#include "smr/extract/session.h"

namespace smr::serve {

struct SessionEntry {
  std::string db;  // the database's name
  std::unique_ptr<Session> session;
  std::mutex busy;          // held by the request updating it
  std::uint64_t frame = 0;  // frames sent (frame 0 included)
  std::chrono::steady_clock::time_point last_used;
};

class SessionTable {
 public:
  SessionTable(std::size_t max_sessions, std::chrono::milliseconds idle)
      : max_(max_sessions), idle_(idle) {}
  /// A new entry for `db` holding `session`, with a fresh random id; nullptr when the table is
  /// full after dropping the idle ones.
  std::shared_ptr<SessionEntry> create(const std::string& db, std::unique_ptr<Session> session,
                                       std::string& id);
  /// The entry `id` of `db` (touched), or nullptr.
  std::shared_ptr<SessionEntry> find(const std::string& db, const std::string& id);
  bool remove(const std::string& db, const std::string& id);
  std::size_t size();

 private:
  void expire(std::chrono::steady_clock::time_point now);  // with mutex_ held
  std::mutex mutex_;
  std::unordered_map<std::string, std::shared_ptr<SessionEntry>> entries_;
  std::size_t max_;
  std::chrono::milliseconds idle_;
  std::uint64_t counter_ = 0;
};

}  // namespace smr::serve
