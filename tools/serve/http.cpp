// smrdb serve's HTTP transport (http.h).
#include "tools/serve/http.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <deque>
#include <mutex>
#include <thread>
#include <vector>

#include <httplib.h>

#include "base/error.h"
#include "tools/serve/static_files.h"

namespace smr::serve {

namespace {

using Clock = std::chrono::steady_clock;

constexpr int kKeepAliveRequests = 5;
constexpr int kKeepAliveIdleMs = 2000;
constexpr std::size_t kMaxBody = 1024;

int remaining_ms(Clock::time_point deadline) {
  const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now());
  return int(std::clamp<std::int64_t>(left.count(), 0, 1 << 30));
}

bool wait_for(int fd, short events, int ms) {
  pollfd p{fd, events, 0};
  for (;;) {
    const int r = ::poll(&p, 1, ms);
    if (r < 0 && errno == EINTR) continue;
    return r > 0 && (p.revents & (events | POLLHUP | POLLERR)) != 0;
  }
}

// A connection as httplib reads and writes it: buffered reads, and every read or write bounded
// by the request's deadline (so a client sending a byte at a time cannot hold a thread).
class DeadlineStream final : public httplib::Stream {
 public:
  explicit DeadlineStream(int fd) : fd_(fd) {}
  void set_deadline(Clock::time_point d) { deadline_ = d; }
  bool close_after = false;  // the answer ends the connection
  bool buffered() const { return pos_ < end_; }

  bool is_readable() const override {
    return buffered() || wait_for(fd_, POLLIN, remaining_ms(deadline_));
  }
  bool is_writable() const override { return wait_for(fd_, POLLOUT, remaining_ms(deadline_)); }
  ssize_t read(char* ptr, std::size_t size) override {
    if (!buffered()) {
      if (!is_readable()) return -1;
      const ssize_t n = ::recv(fd_, buf_, sizeof buf_, MSG_DONTWAIT);
      if (n <= 0) return n < 0 && (errno == EAGAIN || errno == EINTR) ? read(ptr, size) : -1;
      pos_ = 0;
      end_ = std::size_t(n);
    }
    const std::size_t k = std::min(size, end_ - pos_);
    std::memcpy(ptr, buf_ + pos_, k);
    pos_ += k;
    return ssize_t(k);
  }
  ssize_t write(const char* ptr, std::size_t size) override {
    for (;;) {
      if (!is_writable()) return -1;
      const ssize_t n = ::send(fd_, ptr, size, MSG_DONTWAIT | MSG_NOSIGNAL);
      if (n >= 0) return n;
      if (errno != EAGAIN && errno != EINTR) return -1;
    }
  }
  void get_remote_ip_and_port(std::string& ip, int& port) const override {
    address(false, ip, port);
  }
  void get_local_ip_and_port(std::string& ip, int& port) const override { address(true, ip, port); }
  socket_t socket() const override { return fd_; }

 private:
  void address(bool local, std::string& ip, int& port) const {
    sockaddr_storage a{};
    socklen_t len = sizeof a;
    const int r = local ? ::getsockname(fd_, reinterpret_cast<sockaddr*>(&a), &len)
                        : ::getpeername(fd_, reinterpret_cast<sockaddr*>(&a), &len);
    char text[INET6_ADDRSTRLEN] = "";
    port = 0;
    if (r == 0 && a.ss_family == AF_INET) {
      const auto* in = reinterpret_cast<const sockaddr_in*>(&a);
      ::inet_ntop(AF_INET, &in->sin_addr, text, sizeof text);
      port = ntohs(in->sin_port);
    } else if (r == 0 && a.ss_family == AF_INET6) {
      const auto* in = reinterpret_cast<const sockaddr_in6*>(&a);
      ::inet_ntop(AF_INET6, &in->sin6_addr, text, sizeof text);
      port = ntohs(in->sin6_port);
    }
    ip = text;
  }
  int fd_;
  Clock::time_point deadline_ = Clock::now();
  char buf_[4096];
  std::size_t pos_ = 0, end_ = 0;
};

thread_local DeadlineStream* t_stream = nullptr;

// httplib's request parser and response writer, on our connections.
class Parser final : public httplib::Server {
 public:
  bool serve(httplib::Stream& s, bool close, bool& closed) {
    return process_request(s, close, closed, [](httplib::Request&) {});
  }
};

bool httplib_compresses(const std::string& type) {
  return (type.rfind("text/", 0) == 0 && type != "text/event-stream") || type == "image/svg+xml" ||
         type == "application/javascript" || type == "application/json" ||
         type == "application/xml" || type == "application/xhtml+xml";
}

bool gzip(const std::string& in, std::string& out) {
  z_stream zs{};
  if (deflateInit2(&zs, Z_BEST_SPEED, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY) != Z_OK)
    return false;
  out.resize(deflateBound(&zs, uLong(in.size())));
  zs.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(in.data()));
  zs.avail_in = uInt(in.size());
  zs.next_out = reinterpret_cast<Bytef*>(out.data());
  zs.avail_out = uInt(out.size());
  const int r = deflate(&zs, Z_FINISH);
  out.resize(zs.total_out);
  deflateEnd(&zs);
  return r == Z_STREAM_END;
}

std::string canned_503() {
  const std::string body =
      "{\"error\":\"the server is busy (request queue full, --queue): retry later\"}";
  return "HTTP/1.1 503 Service Unavailable\r\nContent-Type: application/json\r\n"
         "Access-Control-Allow-Origin: *\r\nRetry-After: 1\r\nConnection: close\r\n"
         "Content-Length: " +
         std::to_string(body.size()) + "\r\n\r\n" + body;
}

}  // namespace

class HttpServer::Impl {
 public:
  Impl(Api& api, const HttpOptions& o) : api_(api), o_(o) {
    if (!o.viewer_dir.empty()) viewer_ = read_static_files(o.viewer_dir);
    parser_.set_payload_max_length(kMaxBody);
    parser_.set_default_headers({{"Access-Control-Allow-Origin", "*"}});
    parser_.set_error_handler([](const httplib::Request&, httplib::Response& res) {
      if (res.body.empty())
        res.set_content("{\"error\":\"HTTP " + std::to_string(res.status) + "\"}",
                        "application/json");
    });
    parser_.set_pre_routing_handler([this](const httplib::Request& req, httplib::Response& res) {
      respond(req, res);
      if (t_stream != nullptr) t_stream->set_deadline(Clock::now() + timeout());
      return httplib::Server::HandlerResponse::Handled;
    });
    if (o.log)
      parser_.set_logger([](const httplib::Request& req, const httplib::Response& res) {
        std::fprintf(stderr, "%s %s %d %zu\n", req.method.c_str(), req.path.c_str(), res.status,
                     res.body.size());
      });
  }

  int bind();
  void run();
  void stop() {
    stopping_ = true;
    const char c = 1;
    if (stop_pipe_[1] >= 0) (void)!::write(stop_pipe_[1], &c, 1);
  }
  std::size_t viewer_files() const { return viewer_.size(); }
  ~Impl() {
    for (int fd : {listen_fd_, stop_pipe_[0], stop_pipe_[1]})
      if (fd >= 0) ::close(fd);
  }

 private:
  std::chrono::milliseconds timeout() const { return std::chrono::milliseconds(o_.timeout_ms); }
  void respond(const httplib::Request& req, httplib::Response& res);
  void serve_static(const httplib::Request& req, httplib::Response& res);
  void worker();
  void connection(int fd);
  void reject(int fd);
  void dispatch(int fd);  // to the workers' queue, or 503 when it is full

  Api& api_;
  HttpOptions o_;
  StaticFiles viewer_;
  Parser parser_;
  int listen_fd_ = -1;
  int stop_pipe_[2] = {-1, -1};
  std::atomic<bool> stopping_{false};
  std::mutex mutex_;
  std::condition_variable ready_;
  std::deque<int> waiting_;  // accepted connections waiting for a worker
};

void HttpServer::Impl::respond(const httplib::Request& req, httplib::Response& res) {
  if (req.method == "OPTIONS") {  // CORS preflight
    res.status = 204;
    res.set_header("Access-Control-Allow-Methods", "GET, POST, DELETE, OPTIONS");
    res.set_header("Access-Control-Allow-Headers", "*");
    res.set_header("Access-Control-Max-Age", "86400");
    return;
  }
  // No request here has a body, and it is never read: refuse one so that its bytes are not
  // taken for the next request.
  const std::string length = req.get_header_value("Content-Length");
  if ((!length.empty() && length != "0") || req.has_header("Transfer-Encoding")) {
    if (t_stream != nullptr) t_stream->close_after = true;
    res.status = 413;
    res.set_header("Connection", "close");
    res.set_content("{\"error\":\"request bodies are not accepted\"}", "application/json");
    return;
  }
  if (req.path.rfind("/v1/", 0) != 0) return serve_static(req, res);
  Request r{req.method, req.path, {}, req.get_header_value("If-None-Match")};
  for (const auto& [k, v] : req.params) r.params.emplace_back(k, v);
  Response a = api_.handle(r);
  res.status = a.status;
  for (const auto& [k, v] : a.headers) res.set_header(k, v);
  std::string etag = a.etag;
  if (a.status != 304 && a.body.size() >= 256 && !httplib_compresses(a.content_type) &&
      req.get_header_value("Accept-Encoding").find("gzip") != std::string::npos) {
    std::string z;
    if (gzip(a.body, z)) {
      a.body = std::move(z);
      res.set_header("Content-Encoding", "gzip");
      if (!etag.empty()) etag.insert(etag.size() - 1, "-gz");
    }
  }
  res.set_header("Vary", "Accept-Encoding");
  if (!etag.empty()) res.set_header("ETag", etag);
  if (a.status == 304) return;
  res.set_content(std::move(a.body), a.content_type);
}

void HttpServer::Impl::serve_static(const httplib::Request& req, httplib::Response& res) {
  if (req.method != "GET" && req.method != "HEAD") {
    res.status = 405;
    res.set_content("{\"error\":\"only GET outside /v1/\"}", "application/json");
    return;
  }
  if (req.path == "/" && !viewer_.empty()) {
    // The viewer's parameters (?db=...) go along.
    const std::string query = httplib::detail::params_to_query_str(req.params);
    res.set_redirect(query.empty() ? "/index.html" : "/index.html?" + query);
    return;
  }
  const StaticFile* f = find_static_file(viewer_, req.path);
  if (f == nullptr) {
    res.status = 404;
    res.set_content("{\"error\":\"no such file or route\"}", "application/json");
    return;
  }
  res.set_content(f->bytes, f->type);
}

int HttpServer::Impl::bind() {
  if (::pipe2(stop_pipe_, O_CLOEXEC) != 0) throw_io("serve: pipe: " + std::string(strerror(errno)));
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  hints.ai_flags = AI_PASSIVE | AI_NUMERICHOST;
  addrinfo* list = nullptr;
  const std::string port = std::to_string(o_.port);
  if (::getaddrinfo(o_.bind.c_str(), port.c_str(), &hints, &list) != 0 || list == nullptr)
    throw_input("serve: --bind '" + o_.bind + "' is not a numeric IPv4 or IPv6 address");
  listen_fd_ = ::socket(list->ai_family, SOCK_STREAM | SOCK_CLOEXEC, 0);
  const int one = 1;
  ::setsockopt(listen_fd_, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
  const bool ok = listen_fd_ >= 0 && ::bind(listen_fd_, list->ai_addr, list->ai_addrlen) == 0 &&
                  ::listen(listen_fd_, 1024) == 0;
  ::freeaddrinfo(list);
  if (!ok) throw_io("serve: cannot listen on " + o_.bind + ":" + port + ": " + strerror(errno));
  sockaddr_storage a{};
  socklen_t len = sizeof a;
  ::getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&a), &len);
  return ntohs(a.ss_family == AF_INET6 ? reinterpret_cast<sockaddr_in6*>(&a)->sin6_port
                                       : reinterpret_cast<sockaddr_in*>(&a)->sin_port);
}

void HttpServer::Impl::reject(int fd) {
  static const std::string reply = canned_503();
  (void)!::send(fd, reply.data(), reply.size(), MSG_DONTWAIT | MSG_NOSIGNAL);
  ::shutdown(fd, SHUT_WR);
  char sink[512];
  (void)!::recv(fd, sink, sizeof sink, MSG_DONTWAIT);  // what was sent: no reset on close
  ::close(fd);
}

void HttpServer::Impl::connection(int fd) {
  const int one = 1;
  ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
  DeadlineStream s(fd);
  t_stream = &s;
  for (int n = 0; n < kKeepAliveRequests && !stopping_; ++n) {
    // The first request's first byte is there (the acceptor waited for it); a later one's must
    // come within the keep-alive idle time.
    if (n > 0 && !s.buffered() && !wait_for(fd, POLLIN, kKeepAliveIdleMs)) break;
    s.set_deadline(Clock::now() + timeout());
    bool closed = false;
    if (!parser_.serve(s, n + 1 == kKeepAliveRequests, closed) || closed || s.close_after) break;
  }
  t_stream = nullptr;
  ::shutdown(fd, SHUT_RDWR);
  ::close(fd);
}

void HttpServer::Impl::worker() {
  for (;;) {
    int fd = -1;
    {
      std::unique_lock lock(mutex_);
      ready_.wait(lock, [&] { return stopping_ || !waiting_.empty(); });
      if (waiting_.empty()) return;
      fd = waiting_.front();
      waiting_.pop_front();
    }
    connection(fd);
  }
}

void HttpServer::Impl::dispatch(int fd) {
  bool queued = false;
  {
    std::lock_guard lock(mutex_);
    if (waiting_.size() < o_.queue) {
      waiting_.push_back(fd);
      queued = true;
    }
  }
  if (queued)
    ready_.notify_one();
  else
    reject(fd);
}

// The acceptor: new connections wait here, polled, until their first byte arrives (then they go
// to the workers' queue) or --timeout-ms passes (then they are closed), so that connections that
// send nothing hold no worker; at most max_connections of them, beyond which a new one gets 503.
void HttpServer::Impl::run() {
  std::vector<std::thread> workers;
  for (unsigned i = 0; i < std::max(1u, o_.threads); ++i)
    workers.emplace_back([this] { worker(); });
  struct Pending {
    int fd;
    Clock::time_point deadline;
  };
  std::vector<Pending> pending;
  std::vector<pollfd> fds;
  while (!stopping_) {
    fds.assign({{listen_fd_, POLLIN, 0}, {stop_pipe_[0], POLLIN, 0}});
    int wait_ms = 1000;
    for (const Pending& p : pending) {
      fds.push_back({p.fd, POLLIN, 0});
      wait_ms = std::min(wait_ms, remaining_ms(p.deadline) + 1);
    }
    if (::poll(fds.data(), fds.size(), wait_ms) < 0 || (fds[1].revents & POLLIN) != 0) continue;
    const auto now = Clock::now();
    std::size_t kept = 0;
    for (std::size_t i = 0; i < pending.size(); ++i) {
      if (fds[i + 2].revents != 0)
        dispatch(pending[i].fd);  // readable, or closed: a worker finds out which
      else if (now >= pending[i].deadline)
        ::close(pending[i].fd);
      else
        pending[kept++] = pending[i];
    }
    pending.resize(kept);
    if ((fds[0].revents & POLLIN) == 0) continue;
    const int fd = ::accept4(listen_fd_, nullptr, nullptr, SOCK_CLOEXEC);
    if (fd < 0) {
      if (errno == EMFILE || errno == ENFILE)
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
      continue;
    }
    if (pending.size() >= o_.max_connections)
      reject(fd);
    else
      pending.push_back({fd, now + timeout()});
  }
  for (const Pending& p : pending) ::close(p.fd);
  ready_.notify_all();
  for (auto& t : workers) t.join();
  std::lock_guard lock(mutex_);
  for (const int fd : waiting_) ::close(fd);
  waiting_.clear();
}

HttpServer::HttpServer(Api& api, const HttpOptions& options)
    : impl_(std::make_unique<Impl>(api, options)) {}
HttpServer::~HttpServer() = default;
int HttpServer::bind() {
  return impl_->bind();
}
void HttpServer::run() {
  impl_->run();
}
void HttpServer::stop() {
  impl_->stop();
}
std::size_t HttpServer::viewer_files() const {
  return impl_->viewer_files();
}

}  // namespace smr::serve
