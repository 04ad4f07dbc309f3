// A closed-loop HTTP/1.1 load generator for smrdb serve (benchmarks/serve/run_serve_load.sh):
// `--clients` threads, each with one keep-alive connection (reopened when the server closes it),
// request random paths from a list back to back for `--seconds`, and the run prints one JSON
// object: requests/s, latency percentiles, statuses, bytes. Plain sockets, no HTTP library, so
// that smrdb serve and a static file server are driven by the same client.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <random>
#include <string>
#include <thread>
#include <vector>

namespace {

using Clock = std::chrono::steady_clock;

struct Args {
  int port = 8080;
  std::string prefix = "/";
  std::string paths_file;
  int clients = 1;
  double seconds = 10;
  std::uint64_t seed = 1;
  bool once = false;  // every path exactly once (in list order, shared by the clients), then stop
};

std::atomic<std::size_t> g_next{0};  // --once: the next path to request

struct Tally {
  std::vector<double> latency_ms;
  std::map<int, std::uint64_t> status;
  std::uint64_t bytes = 0, errors = 0, connects = 0;
};

int connect_to(int port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(std::uint16_t(port));
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
    ::close(fd);
    return -1;
  }
  const int one = 1;
  ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
  return fd;
}

// One request on `fd`; returns the status (-1: connection failed) and whether the server closes.
int request(int fd, const std::string& path, std::string& buf, std::uint64_t& body_bytes,
            bool& close_after) {
  const std::string req = "GET " + path + " HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n";
  if (::send(fd, req.data(), req.size(), MSG_NOSIGNAL) != ssize_t(req.size())) return -1;
  buf.clear();
  std::size_t header_end = std::string::npos;
  char chunk[65536];
  while (header_end == std::string::npos) {
    const ssize_t n = ::recv(fd, chunk, sizeof chunk, 0);
    if (n <= 0) return -1;
    buf.append(chunk, std::size_t(n));
    header_end = buf.find("\r\n\r\n");
  }
  const int status = std::atoi(buf.c_str() + 9);
  std::string head = buf.substr(0, header_end);
  std::transform(head.begin(), head.end(), head.begin(), ::tolower);
  const std::size_t cl = head.find("content-length:");
  const std::size_t length =
      cl == std::string::npos ? 0 : std::strtoull(head.c_str() + cl + 15, nullptr, 10);
  close_after = head.find("connection: close") != std::string::npos ||
                head.rfind("http/1.0", 0) == 0 || cl == std::string::npos;
  std::size_t have = buf.size() - header_end - 4;
  while (have < length) {
    const ssize_t n = ::recv(fd, chunk, sizeof chunk, 0);
    if (n <= 0) return -1;
    have += std::size_t(n);
  }
  body_bytes += length;
  return status;
}

void client(const Args& a, const std::vector<std::string>& paths, int id, Clock::time_point end,
            Tally& t) {
  std::mt19937_64 rng(a.seed * 1000003 + std::uint64_t(id));
  std::string buf;
  int fd = -1;
  while (Clock::now() < end) {
    if (fd < 0) {
      fd = connect_to(a.port);
      ++t.connects;
      if (fd < 0) {
        ++t.errors;
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
        continue;
      }
    }
    std::size_t i = rng() % paths.size();
    if (a.once && (i = g_next++) >= paths.size()) break;
    const std::string path = a.prefix + paths[i];
    const auto t0 = Clock::now();
    bool close_after = false;
    const int status = request(fd, path, buf, t.bytes, close_after);
    if (status < 0) {
      ++t.errors;
      ::close(fd);
      fd = -1;
      continue;
    }
    t.latency_ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
    ++t.status[status];
    if (close_after) {
      ::close(fd);
      fd = -1;
    }
  }
  if (fd >= 0) ::close(fd);
}

double percentile(std::vector<double>& v, double p) {
  if (v.empty()) return 0;
  const auto k = std::size_t(p * double(v.size() - 1));
  std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(k), v.end());
  return v[k];
}

}  // namespace

int main(int argc, char** argv) {
  Args a;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string k = argv[i], v = argv[i + 1];
    if (k == "--port")
      a.port = std::atoi(v.c_str());
    else if (k == "--prefix")
      a.prefix = v;
    else if (k == "--paths")
      a.paths_file = v;
    else if (k == "--clients")
      a.clients = std::atoi(v.c_str());
    else if (k == "--seconds")
      a.seconds = std::atof(v.c_str());
    else if (k == "--once")
      a.once = v == "1";
    else if (k == "--seed")
      a.seed = std::strtoull(v.c_str(), nullptr, 10);
    else {
      std::fprintf(stderr, "bench_serve_load: unknown option %s\n", k.c_str());
      return 1;
    }
  }
  std::vector<std::string> paths;
  std::ifstream in(a.paths_file);
  for (std::string line; std::getline(in, line);)
    if (!line.empty()) paths.push_back(line);
  if (paths.empty() || a.clients < 1) {
    std::fprintf(stderr, "bench_serve_load: --paths FILE (one path a line) and --clients N >= 1\n");
    return 1;
  }
  std::vector<Tally> tallies(std::size_t(a.clients));
  std::vector<std::thread> threads;
  const auto t0 = Clock::now();
  const auto end =
      t0 + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(a.seconds));
  for (int i = 0; i < a.clients; ++i)
    threads.emplace_back(client, std::cref(a), std::cref(paths), i, end,
                         std::ref(tallies[std::size_t(i)]));
  for (auto& t : threads) t.join();
  const double elapsed = std::chrono::duration<double>(Clock::now() - t0).count();
  Tally all;
  for (auto& t : tallies) {
    all.latency_ms.insert(all.latency_ms.end(), t.latency_ms.begin(), t.latency_ms.end());
    for (const auto& [s, n] : t.status) all.status[s] += n;
    all.bytes += t.bytes;
    all.errors += t.errors;
    all.connects += t.connects;
  }
  const std::size_t n = all.latency_ms.size();
  double sum = 0;
  for (const double l : all.latency_ms) sum += l;
  const double p50 = percentile(all.latency_ms, 0.50), p99 = percentile(all.latency_ms, 0.99);
  std::printf(
      "{\"clients\": %d, \"seconds\": %.3f, \"requests\": %zu, \"rps\": %.1f, "
      "\"p50_ms\": %.3f, \"p99_ms\": %.3f, \"mean_ms\": %.3f, \"errors\": %llu, "
      "\"connects\": %llu, \"bytes\": %llu, \"status\": {",
      a.clients, elapsed, n, double(n) / elapsed, p50, p99, n ? sum / double(n) : 0.0,
      static_cast<unsigned long long>(all.errors), static_cast<unsigned long long>(all.connects),
      static_cast<unsigned long long>(all.bytes));
  bool first = true;
  for (const auto& [s, c] : all.status) {
    std::printf("%s\"%d\": %llu", first ? "" : ", ", s, static_cast<unsigned long long>(c));
    first = false;
  }
  std::printf("}}\n");
  return 0;
}
