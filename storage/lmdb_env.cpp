// The one place LMDB is used (DESIGN.md section 3). Bulk loads use sorted keys with MDB_APPEND;
// every status code goes through one mapping to smr::Error.
#include "storage/lmdb_env.h"

#include <atomic>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <utility>

#include <fcntl.h>
#include <lmdb.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include "storage/error.h"

namespace smr::storage {
namespace {

constexpr std::size_t kTables = std::size(kAllTables);
constexpr unsigned kMaxDbs = 8;

std::size_t index_of(Table table) {
  return static_cast<std::size_t>(table);
}

[[noreturn]] void throw_mdb(int rc, const std::string& where) {
  const std::string message = where + ": " + mdb_strerror(rc);
  switch (rc) {
    case MDB_CORRUPTED:
    case MDB_INVALID:
    case MDB_PAGE_NOTFOUND:
    case MDB_VERSION_MISMATCH:
    case MDB_INCOMPATIBLE:
    case MDB_BAD_VALSIZE:
      throw_corrupt(message);
    default:
      if (rc > 0) throw_io(message);  // an errno value (LMDB's own codes are negative)
      throw_internal(message);
  }
}

void check(int rc, const std::string& where) {
  if (rc != MDB_SUCCESS) throw_mdb(rc, where);
}

MDB_val to_val(ByteView v) {
  return MDB_val{v.size(), const_cast<std::uint8_t*>(v.data())};
}

ByteView from_val(const MDB_val& v) {
  return {static_cast<const std::uint8_t*>(v.mv_data), v.mv_size};
}

std::string errno_text(int err) {
  return std::strerror(err);
}

// Built piecewise: GCC 12 reports a false -Wrestrict on "'" + std::string(...) + "'".
std::string quoted(std::string_view text) {
  std::string out;
  out.reserve(text.size() + 2);
  out.push_back('\'');
  out.append(text);
  out.push_back('\'');
  return out;
}

}  // namespace

std::string_view table_name(Table table) {
  switch (table) {
    case Table::kMeta:
      return "meta";
    case Table::kNodes:
      return "nodes";
    case Table::kPages:
      return "pages";
    case Table::kRtree:
      return "rtree";
    case Table::kAux:
      return "aux";
  }
  return "?";
}

namespace detail {

struct EnvState {
  std::string path;
  MDB_env* env = nullptr;
  MDB_dbi dbis[kTables] = {};
  std::uint64_t file_bytes = 0;
  mutable std::atomic<std::uint64_t> bytes_read{0};

  ~EnvState() {
    if (env != nullptr) mdb_env_close(env);
  }
  std::string where(Table table) const {
    return path + ", table '" + std::string(table_name(table)) + "'";
  }
};

}  // namespace detail

// ---------------------------------------------------------------------------------------------
// Env

Env::Env(std::unique_ptr<detail::EnvState> state) : state_(std::move(state)) {}
Env::Env(Env&&) noexcept = default;
Env& Env::operator=(Env&&) noexcept = default;
Env::~Env() = default;

Env Env::open_read_only(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) {
    throw_io(path + ": cannot open database: " + errno_text(errno));
  }
  if (!S_ISREG(st.st_mode)) throw_input(path + ": not a regular file");
  if (st.st_size == 0) throw_corrupt(path + ": empty file, not an smrdb database");

  auto state = std::make_unique<detail::EnvState>();
  state->path = path;
  state->file_bytes = static_cast<std::uint64_t>(st.st_size);
  check(mdb_env_create(&state->env), path + ": mdb_env_create");
  check(mdb_env_set_maxdbs(state->env, kMaxDbs), path + ": mdb_env_set_maxdbs");
  const int rc =
      mdb_env_open(state->env, path.c_str(),
                   MDB_RDONLY | MDB_NOSUBDIR | MDB_NOTLS | MDB_NOLOCK | MDB_NORDAHEAD, 0);
  if (rc == MDB_INVALID || rc == MDB_VERSION_MISMATCH || rc == ENOENT || rc == EINVAL) {
    throw_corrupt(path + ": not an LMDB database (" + mdb_strerror(rc) + ")");
  }
  check(rc, path + ": cannot open database");

  // A truncated file would map pages past its end (SIGBUS on access): LMDB only checks page
  // numbers against the last page recorded in the meta page, so the file must hold them all.
  MDB_envinfo info{};
  MDB_stat stat{};
  check(mdb_env_info(state->env, &info), path + ": mdb_env_info");
  check(mdb_env_stat(state->env, &stat), path + ": mdb_env_stat");
  const std::uint64_t needed = (static_cast<std::uint64_t>(info.me_last_pgno) + 1) * stat.ms_psize;
  if (needed > state->file_bytes) {
    throw_corrupt(path + ": truncated database: " + std::to_string(state->file_bytes) +
                  " bytes, its pages need " + std::to_string(needed));
  }

  MDB_txn* txn = nullptr;
  check(mdb_txn_begin(state->env, nullptr, MDB_RDONLY, &txn), path + ": mdb_txn_begin");
  for (Table table : kAllTables) {
    const std::string name(table_name(table));
    const int open_rc = mdb_dbi_open(txn, name.c_str(), 0, &state->dbis[index_of(table)]);
    if (open_rc != MDB_SUCCESS) {
      mdb_txn_abort(txn);
      if (open_rc == MDB_NOTFOUND) {
        throw_corrupt(path + ": missing table '" + name + "', not an smrdb database");
      }
      if (open_rc == MDB_INCOMPATIBLE) {
        throw_corrupt(path + ": '" + name + "' is not a table, not an smrdb database");
      }
      throw_mdb(open_rc, state->where(table));
    }
  }
  // Committing a read-only txn keeps the opened DBI handles for the environment.
  check(mdb_txn_commit(txn), path + ": mdb_txn_commit");
  return Env(std::move(state));
}

const std::string& Env::path() const {
  return state_->path;
}
std::uint64_t Env::file_bytes() const {
  return state_->file_bytes;
}
std::uint64_t Env::bytes_read() const {
  return state_->bytes_read.load();
}

ReadTxn Env::read() const {
  MDB_txn* txn = nullptr;
  check(mdb_txn_begin(state_->env, nullptr, MDB_RDONLY, &txn),
        state_->path + ": cannot begin a read transaction");
  return ReadTxn(state_.get(), txn);
}

void Env::release_mapped_pages() const {
  MDB_envinfo info{};
  check(mdb_env_info(state_->env, &info), state_->path + ": mdb_env_info");
  if (info.me_mapaddr == nullptr || info.me_mapsize == 0) return;
  // Advisory: failure only means the pages stay resident.
  (void)::madvise(info.me_mapaddr, info.me_mapsize, MADV_DONTNEED);
}

// ---------------------------------------------------------------------------------------------
// ReadTxn

ReadTxn::ReadTxn(ReadTxn&& other) noexcept
    : env_(std::exchange(other.env_, nullptr)), txn_(std::exchange(other.txn_, nullptr)) {}

ReadTxn& ReadTxn::operator=(ReadTxn&& other) noexcept {
  if (this != &other) {
    if (txn_ != nullptr) mdb_txn_abort(static_cast<MDB_txn*>(txn_));
    env_ = std::exchange(other.env_, nullptr);
    txn_ = std::exchange(other.txn_, nullptr);
  }
  return *this;
}

ReadTxn::~ReadTxn() {
  if (txn_ != nullptr) mdb_txn_abort(static_cast<MDB_txn*>(txn_));
}

std::optional<ByteView> ReadTxn::get_bytes(Table table, ByteView key,
                                           const std::string& key_text) const {
  MDB_val k = to_val(key);
  MDB_val v{};
  const int rc = mdb_get(static_cast<MDB_txn*>(txn_), env_->dbis[index_of(table)], &k, &v);
  if (rc == MDB_NOTFOUND) return std::nullopt;
  if (rc != MDB_SUCCESS) throw_mdb(rc, env_->where(table) + ", key " + key_text);
  env_->bytes_read.fetch_add(v.mv_size, std::memory_order_relaxed);
  return from_val(v);
}

std::optional<ByteView> ReadTxn::get(Table table, std::uint64_t key) const {
  const Bytes k = key_u64(key);
  return get_bytes(table, k, std::to_string(key));
}

std::optional<ByteView> ReadTxn::get(Table table, std::string_view key) const {
  return get_bytes(table, as_bytes(key), quoted(key));
}

void ReadTxn::for_each(Table table,
                       const std::function<void(ByteView key, ByteView value)>& visit) const {
  MDB_cursor* cursor = nullptr;
  check(mdb_cursor_open(static_cast<MDB_txn*>(txn_), env_->dbis[index_of(table)], &cursor),
        env_->where(table) + ": mdb_cursor_open");
  struct Closer {
    MDB_cursor* c;
    ~Closer() { mdb_cursor_close(c); }
  } closer{cursor};
  MDB_val k{}, v{};
  int rc = mdb_cursor_get(cursor, &k, &v, MDB_FIRST);
  while (rc == MDB_SUCCESS) {
    visit(from_val(k), from_val(v));
    rc = mdb_cursor_get(cursor, &k, &v, MDB_NEXT);
  }
  if (rc != MDB_NOTFOUND) throw_mdb(rc, env_->where(table) + ": cursor");
}

std::uint64_t ReadTxn::count(Table table) const {
  MDB_stat st{};
  check(mdb_stat(static_cast<MDB_txn*>(txn_), env_->dbis[index_of(table)], &st),
        env_->where(table) + ": mdb_stat");
  return st.ms_entries;
}

// ---------------------------------------------------------------------------------------------
// DatabaseWriter

namespace {

void remove_quietly(const std::string& path) {
  std::error_code ec;
  std::filesystem::remove(path, ec);
  std::filesystem::remove(path + "-lock", ec);
}

void fsync_path(const std::string& path, bool directory) {
  const int fd = ::open(path.c_str(), (directory ? O_RDONLY | O_DIRECTORY : O_RDONLY) | O_CLOEXEC);
  if (fd < 0) throw_io(path + ": cannot open for fsync: " + errno_text(errno));
  const int rc = ::fsync(fd);
  const int err = errno;
  ::close(fd);
  if (rc != 0) throw_io(path + ": fsync failed: " + errno_text(err));
}

std::string parent_dir(const std::string& path) {
  const std::filesystem::path parent = std::filesystem::path(path).parent_path();
  return parent.empty() ? std::string(".") : parent.string();
}

}  // namespace

DatabaseWriter::DatabaseWriter(std::string path, bool force, std::uint64_t batch_bytes,
                               std::uint64_t initial_map_bytes)
    : path_(std::move(path)),
      batch_bytes_(batch_bytes == 0 ? 1 : batch_bytes),
      map_bytes_(initial_map_bytes < (1u << 16) ? (1u << 16) : initial_map_bytes) {
  std::error_code ec;
  if (std::filesystem::exists(path_, ec) && !force) {
    throw_input(path_ + ": exists; pass --force to replace it");
  }
  if (std::filesystem::is_directory(path_, ec)) throw_input(path_ + ": is a directory");
  tmp_path_ = path_ + ".tmp-" + std::to_string(::getpid());
  compact_path_ = tmp_path_ + ".compact";
  remove_quietly(tmp_path_);
  remove_quietly(compact_path_);

  MDB_env* env = nullptr;
  check(mdb_env_create(&env), tmp_path_ + ": mdb_env_create");
  env_ = env;
  try {
    check(mdb_env_set_maxdbs(env, kMaxDbs), tmp_path_ + ": mdb_env_set_maxdbs");
    check(mdb_env_set_mapsize(env, map_bytes_), tmp_path_ + ": mdb_env_set_mapsize");
    // Single writer, temporary file: no lock file, no syncs (finish() fsyncs the compact copy).
    check(mdb_env_open(env, tmp_path_.c_str(), MDB_NOSUBDIR | MDB_NOLOCK | MDB_NOSYNC, 0644),
          tmp_path_ + ": cannot create database");
    MDB_txn* txn = nullptr;
    check(mdb_txn_begin(env, nullptr, 0, &txn), tmp_path_ + ": mdb_txn_begin");
    for (Table table : kAllTables) {
      const std::string name(table_name(table));
      const int rc = mdb_dbi_open(txn, name.c_str(), MDB_CREATE, &dbis_[index_of(table)]);
      if (rc != MDB_SUCCESS) {
        mdb_txn_abort(txn);
        throw_mdb(rc, tmp_path_ + ", table '" + name + "'");
      }
    }
    check(mdb_txn_commit(txn), tmp_path_ + ": mdb_txn_commit");
  } catch (...) {
    cleanup();
    throw;
  }
}

DatabaseWriter::~DatabaseWriter() {
  cleanup();
}

void DatabaseWriter::cleanup() noexcept {
  if (env_ != nullptr) {
    mdb_env_close(static_cast<MDB_env*>(env_));
    env_ = nullptr;
  }
  if (!tmp_path_.empty()) {
    remove_quietly(tmp_path_);
    remove_quietly(compact_path_);
  }
}

void DatabaseWriter::append(Table table, std::uint64_t key, ByteView value) {
  std::optional<std::uint64_t>& last = last_key_[index_of(table)];
  if (last && key <= *last) {
    throw_internal(path_ + ", table '" + std::string(table_name(table)) + "': key " +
                   std::to_string(key) + " appended after key " + std::to_string(*last) +
                   " (keys must be strictly increasing)");
  }
  last = key;
  const Bytes k = key_u64(key);
  add(table, k, value, true);
}

void DatabaseWriter::put(Table table, std::string_view key, ByteView value) {
  add(table, as_bytes(key), value, false);
}

void DatabaseWriter::add(Table table, ByteView key, ByteView value, bool append) {
  if (finished_ || env_ == nullptr) throw_internal(path_ + ": write after finish()");
  if (key.empty() || key.size() > 511) {
    throw_internal(path_ + ", table '" + std::string(table_name(table)) + "': key of " +
                   std::to_string(key.size()) + " bytes (LMDB keys are 1..511 bytes)");
  }
  Op op{table, append, arena_.size(), key.size(), 0, value.size()};
  arena_.insert(arena_.end(), key.begin(), key.end());
  op.value_offset = arena_.size();
  arena_.insert(arena_.end(), value.begin(), value.end());
  ops_.push_back(op);
  bytes_written_ += value.size();
  if (arena_.size() >= batch_bytes_) flush();
}

void DatabaseWriter::flush() {
  if (ops_.empty()) return;
  auto* env = static_cast<MDB_env*>(env_);
  for (;;) {
    MDB_txn* txn = nullptr;
    check(mdb_txn_begin(env, nullptr, 0, &txn), tmp_path_ + ": mdb_txn_begin");
    int rc = MDB_SUCCESS;
    const Op* failed = nullptr;
    for (const Op& op : ops_) {
      MDB_val k{op.key_size, arena_.data() + op.key_offset};
      MDB_val v{op.value_size, arena_.data() + op.value_offset};
      rc = mdb_put(txn, dbis_[index_of(op.table)], &k, &v, op.append ? MDB_APPEND : 0);
      if (rc != MDB_SUCCESS) {
        failed = &op;
        break;
      }
    }
    if (rc == MDB_SUCCESS) {
      rc = mdb_txn_commit(txn);  // frees the txn whatever the outcome
    } else {
      mdb_txn_abort(txn);
    }
    if (rc == MDB_SUCCESS) break;
    if (rc == MDB_MAP_FULL) {
      // Grow and redo the whole batch (the aborted txn left nothing behind).
      map_bytes_ *= 2;
      check(mdb_env_set_mapsize(env, map_bytes_), tmp_path_ + ": mdb_env_set_mapsize");
      continue;
    }
    std::string where = path_;
    if (failed != nullptr) {
      where += ", table '" + std::string(table_name(failed->table)) + "', key ";
      const ByteView key(arena_.data() + failed->key_offset, failed->key_size);
      where +=
          failed->append
              ? std::to_string(parse_key_u64(key, where))
              : quoted(std::string_view(reinterpret_cast<const char*>(key.data()), key.size()));
    } else {
      where += ": commit";
    }
    throw_mdb(rc, where);
  }
  ++commits_;
  ops_.clear();
  arena_.clear();
}

void DatabaseWriter::finish() {
  if (finished_ || env_ == nullptr) throw_internal(path_ + ": finish() called twice");
  flush();
  auto* env = static_cast<MDB_env*>(env_);
  const int fd = ::open(compact_path_.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw_io(compact_path_ + ": cannot create: " + errno_text(errno));
  int rc = mdb_env_copyfd2(env, fd, MDB_CP_COMPACT);
  if (rc == MDB_SUCCESS && ::fsync(fd) != 0) rc = errno;
  if (::close(fd) != 0 && rc == MDB_SUCCESS) rc = errno;
  check(rc, compact_path_ + ": writing the compacted database");
  mdb_env_close(env);
  env_ = nullptr;
  if (::rename(compact_path_.c_str(), path_.c_str()) != 0) {
    throw_io(path_ + ": cannot rename " + compact_path_ + " over it: " + errno_text(errno));
  }
  finished_ = true;
  remove_quietly(tmp_path_);
  fsync_path(parent_dir(path_), true);
}

}  // namespace smr::storage
