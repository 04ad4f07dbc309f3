// The project's one error type (STYLE.md: "pick one and keep it"): exceptions carrying a
// category and a message a user can act on (which file, record or parameter, what was expected).
#pragma once

#include <stdexcept>
#include <string>

namespace smr {

enum class ErrorKind {
  kInvalidInput,  // bad file, bad parameter, unsupported data: the user can fix it (exit 1)
  kIo,            // the operating system refused (missing file, permissions, disk full) (exit 1)
  kCorrupt,       // stored data failed validation (exit 1)
  kInternal,      // a broken invariant: a bug in smrdb (exit 2)
};

class Error : public std::runtime_error {
 public:
  Error(ErrorKind kind, const std::string& message) : std::runtime_error(message), kind_(kind) {}
  ErrorKind kind() const { return kind_; }
  int exit_code() const { return kind_ == ErrorKind::kInternal ? 2 : 1; }

 private:
  ErrorKind kind_;
};

[[noreturn]] inline void throw_input(const std::string& message) {
  throw Error(ErrorKind::kInvalidInput, message);
}
[[noreturn]] inline void throw_io(const std::string& message) {
  throw Error(ErrorKind::kIo, message);
}
[[noreturn]] inline void throw_corrupt(const std::string& message) {
  throw Error(ErrorKind::kCorrupt, message);
}
[[noreturn]] inline void throw_internal(const std::string& message) {
  throw Error(ErrorKind::kInternal, message);
}

}  // namespace smr
