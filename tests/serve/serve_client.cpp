// The client side of the serve tests (serve_client.h).
#include "tests/serve/serve_client.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <fstream>
#include <sstream>
#include <thread>

#include <gtest/gtest.h>

#include "tests/support/process.h"

namespace smr::test {

ServerProcess::ServerProcess(std::vector<std::string> args, const std::string& log_path) {
  args.insert(args.begin(), {SMRDB_BIN, "serve"});
  args.insert(args.end(), {"--port", "0"});
  pid_ = spawn(args, log_path);
  const std::string marker = "listening on http://127.0.0.1:";
  for (int i = 0; i < 400 && port_ == 0 && alive(); ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(25));
    std::ifstream in(log_path);
    std::stringstream text;
    text << in.rdbuf();
    const std::size_t at = text.str().find(marker);
    if (at != std::string::npos) port_ = std::atoi(text.str().c_str() + at + marker.size());
  }
  if (port_ == 0) ADD_FAILURE() << "smrdb serve did not start (see " << log_path << ")";
}

ServerProcess::~ServerProcess() {
  if (pid_ > 0) stop();
}

bool ServerProcess::alive() const {
  return pid_ > 0 && ::kill(pid_, 0) == 0 && ::waitpid(pid_, nullptr, WNOHANG) == 0;
}

int ServerProcess::stop() {
  if (pid_ <= 0) return -1;
  ::kill(pid_, SIGTERM);
  const Exit e = kill_after(pid_, 10.0);
  pid_ = -1;
  return e.status;
}

RawSocket::RawSocket(int port) {
  fd_ = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(std::uint16_t(port));
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::connect(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
    ::close(fd_);
    fd_ = -1;
  }
}

RawSocket::~RawSocket() {
  if (fd_ >= 0) ::close(fd_);
}

bool RawSocket::send(const std::string& bytes) {
  return fd_ >= 0 && ::send(fd_, bytes.data(), bytes.size(), MSG_NOSIGNAL) == ssize_t(bytes.size());
}

namespace {

bool complete_response(const std::string& r) {
  const std::size_t end = r.find("\r\n\r\n");
  if (end == std::string::npos) return false;
  const std::size_t at = r.find("Content-Length: ");
  if (at == std::string::npos || at > end) return false;
  return r.size() >= end + 4 + std::stoul(r.substr(at + 16));
}

}  // namespace

std::string RawSocket::read_all(int timeout_ms, bool one_response) {
  std::string out;
  const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  while (fd_ >= 0) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        end - std::chrono::steady_clock::now());
    if (left.count() <= 0) break;
    pollfd p{fd_, POLLIN, 0};
    if (::poll(&p, 1, int(left.count())) <= 0) break;
    char buf[4096];
    const ssize_t n = ::recv(fd_, buf, sizeof buf, 0);
    if (n <= 0) break;
    out.append(buf, std::size_t(n));
    if (one_response && complete_response(out)) break;
  }
  return out;
}

bool RawSocket::closed_within(int timeout_ms) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  while (fd_ >= 0) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        end - std::chrono::steady_clock::now());
    if (left.count() <= 0) return false;
    pollfd p{fd_, POLLIN, 0};
    if (::poll(&p, 1, int(left.count())) <= 0) return false;
    char buf[4096];
    if (::recv(fd_, buf, sizeof buf, 0) <= 0) return true;
  }
  return true;
}

namespace {

class Reader {
 public:
  explicit Reader(const std::string& b) : b_(b) {}
  template <class T>
  T get() {
    T v{};
    if (at_ + sizeof(T) > b_.size()) {
      ok_ = false;
      return v;
    }
    std::memcpy(&v, b_.data() + at_, sizeof(T));
    at_ += sizeof(T);
    return v;
  }
  std::string text(std::size_t n) {
    if (at_ + n > b_.size()) {
      ok_ = false;
      return {};
    }
    at_ += n;
    return b_.substr(at_ - n, n);
  }
  void align4() { at_ = (at_ + 3) & ~std::size_t{3}; }
  bool ok() const { return ok_; }
  std::size_t at() const { return at_; }

 private:
  const std::string& b_;
  std::size_t at_ = 0;
  bool ok_ = true;
};

}  // namespace

DecodedFrame decode_frame(const std::string& bytes) {
  DecodedFrame f;
  Reader r(bytes);
  EXPECT_EQ(r.text(4), "SMRF");
  EXPECT_EQ(r.get<std::uint32_t>(), 1u);
  const auto json_bytes = r.get<std::uint32_t>();
  f.header = nlohmann::json::parse(r.text(json_bytes));
  r.align4();
  const auto n_out = f.header["n_out"].get<std::size_t>();
  const auto n_in = f.header["n_in"].get<std::size_t>();
  const auto n_mv = f.header["n_mv"].get<std::size_t>();
  const auto n_mt = f.header["n_mt"].get<std::size_t>();
  auto key = [&] {
    std::array<std::uint32_t, 3> k{};
    for (auto& v : k) v = r.get<std::uint32_t>();
    return k;
  };
  for (std::size_t i = 0; i < n_out; ++i) f.out.push_back(key());
  f.in.resize(n_in);
  for (auto& t : f.in) t.key = key();
  for (auto& t : f.in)
    for (auto& v : t.pos) v = r.get<float>();
  for (auto& t : f.in) t.flags = r.get<std::uint8_t>();
  r.align4();
  auto vec = [&] {
    std::array<float, 3> p{};
    for (auto& v : p) v = r.get<float>();
    return p;
  };
  for (std::size_t i = 0; i < n_mv; ++i) f.m_start.push_back(vec());
  for (std::size_t i = 0; i < n_mv; ++i) f.m_end.push_back(vec());
  for (std::size_t i = 0; i < n_mv; ++i) f.m_group.push_back(r.get<std::uint32_t>());
  for (std::size_t i = 0; i < n_mt; ++i) f.m_tris.push_back(key());
  for (std::size_t i = 0; i < n_mt; ++i) f.m_flags.push_back(r.get<std::uint8_t>());
  r.align4();
  EXPECT_TRUE(r.ok()) << "frame shorter than its header says";
  EXPECT_EQ(r.at(), bytes.size()) << "frame longer than its header says";
  return f;
}

}  // namespace smr::test
