// The LMDB environment of one database file (docs/design.md section 3): one file holding the tables
// its caller names, read-only access for readers and an atomic, deterministic writer. LMDB types
// never appear here; every LMDB status becomes an smr::Error carrying mdb_strerror's text and the
// path/table/key involved. Storage knows no table of its own: the caller passes the list of
// table names (the LMDB sub-database names) to Env::open_read_only and DatabaseWriter, and
// addresses a table by its index in that list.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include "storage/bytes.h"

namespace smr::storage {

// A table of an Env or a DatabaseWriter: the index of its name in the list the file was opened
// or created with. A caller names its tables with an enum whose values are those indices; the
// enum converts implicitly.
class Table {
 public:
  constexpr explicit Table(std::size_t index) : index_(index) {}
  template <class E>
  requires std::is_enum_v<E>
  constexpr Table(E table) : index_(static_cast<std::size_t>(table)) {}  // NOLINT: implicit
  constexpr std::size_t index() const { return index_; }
  friend constexpr bool operator==(Table, Table) = default;

 private:
  std::size_t index_;
};

// The most tables a file may have (LMDB's maxdbs).
inline constexpr std::size_t kMaxTables = 8;

class ReadTxn;

namespace detail {
struct EnvState;
}

// A database file opened for reading. Move-only; closing unmaps the file.
class Env {
 public:
  // Opens with MDB_RDONLY|MDB_NOSUBDIR|MDB_NOTLS|MDB_NOLOCK|MDB_NORDAHEAD: database files are never
  // modified after creation, so no lock file is needed and any number of threads and processes
  // may read. `tables` names the tables to open (Table(i) is tables[i]; at most kMaxTables, no
  // name twice, kInternal otherwise); the file may hold others. A missing file (kIo), an empty,
  // truncated or non-LMDB file or a missing table (kCorrupt) throws smr::Error naming the path.
  // LMDB trusts the file's structure, so each page is checked before LMDB first reads it (the meta
  // pages and the table of tables here, the pages on the way to a key in get() and for_each()): a
  // damaged page throws kCorrupt naming the path, the table and the page instead of crashing the
  // process.
  static Env open_read_only(const std::string& path, std::span<const std::string_view> tables);

  Env(Env&&) noexcept;
  Env& operator=(Env&&) noexcept;
  ~Env();

  const std::string& path() const;
  std::uint64_t file_bytes() const;
  const std::string& table_name(Table table) const;

  // A read-only transaction (a consistent snapshot). It may be created and used on any thread
  // (MDB_NOTLS), but one transaction must not be used by two threads at the same time.
  ReadTxn read() const;

  // Drops this process's mapping of the file's pages (madvise MADV_DONTNEED over the whole map)
  // so that pages read earlier stop counting in RSS. Call only while no ByteView obtained from a
  // transaction is in use (the data stays valid but is faulted in again from the page cache).
  void release_mapped_pages() const;

  // Total bytes of values returned by ReadTxn::get() on transactions of this Env.
  std::uint64_t bytes_read() const;

 private:
  explicit Env(std::unique_ptr<detail::EnvState> state);
  std::unique_ptr<detail::EnvState> state_;
};

// Move-only. ByteViews returned by get()/for_each() stay valid until the transaction is destroyed.
// The Env must outlive its transactions.
class ReadTxn {
 public:
  ReadTxn(ReadTxn&&) noexcept;
  ReadTxn& operator=(ReadTxn&&) noexcept;
  ~ReadTxn();

  // A value over a page is asked of the OS whole (the file is opened MDB_NORDAHEAD), or only its
  // first `head` bytes for a reader of its head.
  static constexpr std::size_t kWhole = ~std::size_t{0};
  std::optional<ByteView> get(Table table, std::uint64_t key,
                              std::size_t head = kWhole) const;  // key_u64(key)
  std::optional<ByteView> get(Table table, std::string_view key) const;
  // Asks the OS to start reading the values of `keys` (those stored on pages of their own, or
  // their first `head` bytes) without waiting for them: get() on them later finds them read, or in
  // flight together.
  void will_need(Table table, std::span<const std::uint64_t> keys, std::size_t head = kWhole) const;
  // The same for values kept in their tree's leaf pages (small ones): asks for the keys' leaves,
  // reading only branch pages meanwhile.
  void will_need_leaves(Table table, std::span<const std::uint64_t> keys) const;
  // Every entry of `table` in key order.
  void for_each(Table table, const std::function<void(ByteView key, ByteView value)>& visit) const;
  std::uint64_t count(Table table) const;

 private:
  friend class Env;
  ReadTxn(const detail::EnvState* env, void* txn) : env_(env), txn_(txn) {}
  std::optional<ByteView> get_bytes(Table table, ByteView key, const std::string& key_text,
                                    std::size_t head) const;

  const detail::EnvState* env_ = nullptr;
  void* txn_ = nullptr;  // MDB_txn*
};

// Writes a NEW database file atomically and deterministically.
//
// Writes go to a temporary LMDB file "<path>.tmp-<pid>" in the same directory. finish() commits,
// writes a compacted copy (mdb_env_copyfd2 with MDB_CP_COMPACT) to "<path>.tmp-<pid>.compact",
// fsyncs it, renames it over <path>, fsyncs the directory and removes the temporaries. The
// caller writes the `meta` table LAST, so a reader never sees a database without its meta.
// A kill -9 at any moment leaves <path> either as it was or complete (at worst a stale
// "<path>.tmp-*" file remains). The same sequence of calls produces a byte-identical file.
// Every table named at construction exists in the output, possibly empty; LMDB creates them in
// the order of the list (part of what makes the bytes).
class DatabaseWriter {
 public:
  // `tables` names the file's tables, as Env::open_read_only takes them. Throws kInvalidInput
  // "<path>: exists; pass --force to replace it" if <path> exists and !force, before touching
  // anything. Writes are committed every `batch_bytes`; the map starts at `initial_map_bytes` and
  // doubles whenever LMDB reports MDB_MAP_FULL (the batch is redone; the caller never sees
  // MDB_MAP_FULL).
  DatabaseWriter(std::string path, std::span<const std::string_view> tables, bool force,
                 std::uint64_t batch_bytes = 64u << 20,
                 std::uint64_t initial_map_bytes = 64u << 20);
  DatabaseWriter(const DatabaseWriter&) = delete;
  DatabaseWriter& operator=(const DatabaseWriter&) = delete;
  // Without finish(): removes every temporary and leaves <path> untouched.
  ~DatabaseWriter();

  // Keys must be strictly increasing per table (bulk load with MDB_APPEND); a key not greater
  // than the previous one appended to that table throws kInternal.
  void append(Table table, std::uint64_t key, ByteView value);
  // Any key, any order; a later put of the same key replaces the value.
  void put(Table table, std::string_view key, ByteView value);
  // Commit, compact, rename. The writer is unusable afterwards.
  void finish();

  const std::string& path() const { return path_; }
  const std::string& table_name(Table table) const;
  std::uint64_t bytes_written() const { return bytes_written_; }  // value bytes accepted
  std::uint64_t commits() const { return commits_; }              // LMDB write txns committed
  std::uint64_t map_bytes() const { return map_bytes_; }          // current map size

 private:
  struct Op {
    Table table;
    bool append;
    std::size_t key_offset, key_size, value_offset, value_size;
  };
  void add(Table table, ByteView key, ByteView value, bool append);
  // Where LMDB mapped the file written so far (after a commit), or nullptr if it cannot tell.
  const std::uint8_t* mapping_of_written() const;
  // Drops the map's resident pages (after a commit): see flush().
  void drop_mapped_pages();
  /// LMDB's compacting copy of the written database to `fd`, through a pipe whose pump drops
  /// `map`'s pages as it goes (lmdb_env.cpp); 0 or an errno/LMDB code.
  int copy_through_pump(void* env, int fd, const std::uint8_t* map) const;
  void flush();
  void cleanup() noexcept;

  std::string path_, tmp_path_, compact_path_;
  std::vector<std::string> tables_;  // the table names, by Table index
  std::uint64_t batch_bytes_;
  std::uint64_t map_bytes_;
  void* env_ = nullptr;                                 // MDB_env*
  std::vector<unsigned> dbis_;                          // MDB_dbi per Table
  std::vector<Op> ops_;                                 // the pending batch
  Bytes arena_;                                         // keys and values of the pending batch
  std::vector<std::optional<std::uint64_t>> last_key_;  // per Table
  std::uint64_t bytes_written_ = 0, commits_ = 0;
  const std::uint8_t* map_ = nullptr;  // mapping_of_written(), found for a map of map_found_bytes_
  std::uint64_t map_found_bytes_ = 0;
  bool finished_ = false;
};

}  // namespace smr::storage
