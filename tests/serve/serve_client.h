// The client side of the serve tests: a spawned `smrdb serve`, raw sockets, and a decoder of the
// session frames (docs/serve.md, "Frame") written from the spec.
#pragma once

#include <sys/types.h>

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace smr::test {

/// `smrdb serve ARGS --port 0` started, its port read from its first line.
class ServerProcess {
 public:
  explicit ServerProcess(std::vector<std::string> args, const std::string& log_path);
  ~ServerProcess();
  int port() const { return port_; }
  bool alive() const;
  /// SIGTERM, then the exit status as waitpid gives it (a normal exit: WIFEXITED).
  int stop();

 private:
  pid_t pid_ = -1;
  int port_ = 0;
};

/// A raw TCP connection to 127.0.0.1:port.
class RawSocket {
 public:
  explicit RawSocket(int port);
  ~RawSocket();
  bool send(const std::string& bytes);
  /// Everything until the peer closes or `timeout_ms` passes (`one_response`: or a whole
  /// response with a Content-Length has arrived).
  std::string read_all(int timeout_ms, bool one_response = false);
  /// Whether the peer has closed (a read returns 0 or an error) within `timeout_ms`.
  bool closed_within(int timeout_ms);
  int fd() const { return fd_; }

 private:
  int fd_ = -1;
};

struct FrameTriangle {
  std::array<std::uint32_t, 3> key{};
  std::array<float, 9> pos{};
  std::uint8_t flags = 0;
};

struct DecodedFrame {
  nlohmann::json header;
  std::vector<std::array<std::uint32_t, 3>> out;
  std::vector<FrameTriangle> in;
  std::vector<std::array<float, 3>> m_start, m_end;
  std::vector<std::uint32_t> m_group;
  std::vector<std::array<std::uint32_t, 3>> m_tris;
  std::vector<std::uint8_t> m_flags;
};

/// Decodes a frame; a malformed one fails the current test (and returns what was read).
DecodedFrame decode_frame(const std::string& bytes);

}  // namespace smr::test
