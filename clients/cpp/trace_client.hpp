// trace_client.hpp: a C++17 client of trace-recorder (schemas/PROFILE.md section 13).
//
// Header-only; needs the C++ standard library and POSIX sockets, nothing else. A control
// loop hands each decision cycle, as one JSON object, to Client::send_cycle(), which copies
// it into a preallocated ring buffer and returns: it never blocks, never allocates (for a
// cycle up to Options::max_cycle_bytes) and never makes a system call. A background sender
// thread, looking at the ring every poll interval, connects, says hello,
// frames the cycles (4-byte big-endian length + JSON), sends them, counts the recorder's
// error replies, and reconnects with a growing pause when the recorder goes away. A full
// ring or a lost connection drops the cycle and counts it; the next cycle sent declares
// the drops, so the robot's chain says where its record has holes.
//
//   trace::Client client({.socket_path = "/run/trace/recorder.sock", .robot_id = "amr-7",
//                         .period_ns = 20'000'000});
//   client.wait_connected(std::chrono::seconds(2));
//   trace::JsonWriter w;                      // reuse one writer: clear() keeps its memory
//   w.begin_object().key("t_ns").value(t_ns).key("action").begin_object() ... .end_object();
//   client.send_cycle(w.str());               // false: dropped and counted
//   client.close();                           // send what is queued, say bye
#pragma once

#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <charconv>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdint>
#include <cstring>
#include <mutex>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

namespace trace {

constexpr int kProtocolVersion = 1;
constexpr std::size_t kMaxFrameBytes = 4 * 1024 * 1024;  // the recorder's default limit

// Compact JSON appended to one reusable string; commas are placed by the writer. Doubles are
// written in their shortest exact form and always as numbers with a '.' or an exponent (so
// 1.0 stays a float for the reader); NaN and infinities, which JSON cannot hold, as null.
class JsonWriter {
 public:
  explicit JsonWriter(std::size_t reserve = 8192) { out_.reserve(reserve); }
  void clear() { out_.clear(); comma_ = false; }
  const std::string& str() const { return out_; }

  JsonWriter& begin_object() { sep(); out_ += '{'; comma_ = false; return *this; }
  JsonWriter& end_object() { out_ += '}'; comma_ = true; return *this; }
  JsonWriter& begin_array() { sep(); out_ += '['; comma_ = false; return *this; }
  JsonWriter& end_array() { out_ += ']'; comma_ = true; return *this; }
  JsonWriter& key(std::string_view k) { sep(); quoted(k); out_ += ':'; comma_ = false; return *this; }
  JsonWriter& value(std::string_view s) { sep(); quoted(s); comma_ = true; return *this; }
  JsonWriter& value(const char* s) { return value(std::string_view(s)); }
  JsonWriter& value(bool b) { sep(); out_ += b ? "true" : "false"; comma_ = true; return *this; }
  JsonWriter& null() { sep(); out_ += "null"; comma_ = true; return *this; }
  JsonWriter& value(std::int64_t n) { sep(); digits(n); comma_ = true; return *this; }
  JsonWriter& value(int n) { return value(static_cast<std::int64_t>(n)); }
  JsonWriter& value(double d) {
    if (!std::isfinite(d)) return null();
    sep();
    char buf[32];
    auto res = std::to_chars(buf, buf + sizeof buf, d);
    std::string_view text(buf, static_cast<std::size_t>(res.ptr - buf));
    out_.append(text);
    if (text.find_first_of(".e") == std::string_view::npos) out_ += ".0";
    comma_ = true;
    return *this;
  }
  // A value already written as JSON (a sensor payload kept as text).
  JsonWriter& raw(std::string_view json) { sep(); out_.append(json); comma_ = true; return *this; }

 private:
  void sep() { if (comma_) out_ += ','; }
  void digits(std::int64_t n) {
    char buf[24];
    auto res = std::to_chars(buf, buf + sizeof buf, n);
    out_.append(buf, static_cast<std::size_t>(res.ptr - buf));
  }
  void quoted(std::string_view s) {
    out_ += '"';
    std::size_t run = 0;  // characters that need no escape are appended in one piece
    for (std::size_t i = 0; i < s.size(); ++i) {
      auto u = static_cast<unsigned char>(s[i]);
      if (u >= 0x20 && u != '"' && u != '\\') continue;
      out_.append(s.data() + run, i - run);
      run = i + 1;
      if (u >= 0x20) { out_ += '\\'; out_ += s[i]; continue; }
      static const char hex[] = "0123456789abcdef";
      out_ += "\\u00"; out_ += hex[u >> 4]; out_ += hex[u & 15];
    }
    out_.append(s.data() + run, s.size() - run);
    out_ += '"';
  }
  std::string out_;
  bool comma_ = false;
};

struct Options {
  std::string socket_path;       // the recorder's Unix socket, or
  std::string tcp_host;          // a loopback TCP address (used when socket_path is empty)
  std::uint16_t tcp_port = 0;
  std::string robot_id;
  std::int64_t period_ns = 100'000'000;
  std::string clock = "system";  // system, monotonic, sim, ...
  std::string software_version;
  std::string policy_version;
  std::string profile = "1";
  std::size_t ring_slots = 64;   // cycles the ring holds before send_cycle() drops
  std::size_t max_cycle_bytes = 64 * 1024;  // longer cycles are dropped (and counted)
  std::chrono::milliseconds connect_timeout{1000};
  std::chrono::milliseconds backoff_min{50};
  std::chrono::milliseconds backoff_max{1000};
  // How often the sender looks for cycles; 0: an eighth of the period, from 0.2 to 5 ms.
  std::chrono::microseconds poll_interval{0};
};

class Client {
 public:
  explicit Client(Options options)
      : opt_(std::move(options)), slots_(std::max<std::size_t>(opt_.ring_slots, 1)) {
    for (auto& slot : slots_) {  // touched now: a first write must not page-fault later
      slot.assign(opt_.max_cycle_bytes, '\0');
      slot.clear();
    }
    poll_ = opt_.poll_interval.count() > 0
                ? opt_.poll_interval
                : std::chrono::microseconds(std::clamp<std::int64_t>(opt_.period_ns / 8000, 200, 5000));
    frame_.reserve(opt_.max_cycle_bytes + 128);
    sender_ = std::thread([this] { run(); });
  }
  ~Client() { close(); }
  Client(const Client&) = delete;
  Client& operator=(const Client&) = delete;

  // Control thread. Copies the cycle (a JSON object: t_ns, perception, belief, action,
  // execution, sensors) into the ring; false when it was dropped (no recorder connected,
  // ring full, too long, not an object). Never blocks.
  bool send_cycle(std::string_view cycle_json) {
    if (!connected_.load(std::memory_order_acquire)) { bump(dropped_disconnected_); return false; }
    if (cycle_json.size() < 2 || cycle_json.size() > opt_.max_cycle_bytes ||
        cycle_json.front() != '{') {
      bump(dropped_invalid_);
      return false;
    }
    const std::uint64_t tail = tail_.load(std::memory_order_relaxed);
    if (tail - head_.load(std::memory_order_acquire) >= slots_.size()) { bump(dropped_full_); return false; }
    slots_[tail % slots_.size()].assign(cycle_json.data(), cycle_json.size());
    tail_.store(tail + 1, std::memory_order_release);
    return true;  // no wake-up: the sender looks every poll interval (see run())
  }

  // Wait (not on the control loop: at start-up) until the recorder has welcomed us.
  bool wait_connected(std::chrono::milliseconds timeout) {
    auto until = std::chrono::steady_clock::now() + timeout;
    while (!connected_.load() && std::chrono::steady_clock::now() < until && !refused_hello_.load())
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    return connected_.load();
  }

  // Send what is queued (waiting at most `timeout`), say bye, and stop the sender thread.
  void close(std::chrono::milliseconds timeout = std::chrono::milliseconds(5000)) {
    if (!sender_.joinable()) return;
    close_by_ = std::chrono::steady_clock::now() + timeout;
    stop_.store(true);
    wake_.notify_one();
    sender_.join();
  }

  std::uint64_t sent() const { return sent_.load(); }
  std::uint64_t refused() const { return refused_.load(); }    // error replies
  std::uint64_t connects() const { return connects_.load(); }
  bool connected() const { return connected_.load(); }
  std::uint64_t dropped() const {
    return dropped_disconnected_.load() + dropped_full_.load() + dropped_invalid_.load() +
           dropped_unsent_.load();
  }

 private:
  using Clock = std::chrono::steady_clock;
  // One writing thread per counter: a relaxed load and store, no locked instruction.
  static void bump(std::atomic<std::uint64_t>& c, std::uint64_t n = 1) {
    c.store(c.load(std::memory_order_relaxed) + n, std::memory_order_relaxed);
  }

  void run() {
    auto pause = opt_.backoff_min;
    while (true) {
      if (fd_ < 0) {
        if (stop_.load()) break;
        if (!connect_and_hello()) {
          discard_ring();
          sleep_unless_stopped(pause);
          pause = std::min(pause * 2, opt_.backoff_max);
          continue;
        }
        pause = opt_.backoff_min;
      }
      send_ring();
      read_replies(0);
      if (stop_.load()) {
        send_ring();
        say_bye();
        break;
      }
      // The sender looks at the ring every poll interval instead of being woken: a wake-up
      // from the control thread is a system call, and on a busy machine the woken sender
      // can take the control thread's core for the whole send (measured: p50 220 us).
      sleep_unless_stopped(poll_);
    }
    discard_ring();
    disconnect();
  }

  template <class Duration>
  void sleep_unless_stopped(Duration pause) {
    std::unique_lock<std::mutex> lock(mu_);
    wake_.wait_for(lock, pause, [this] { return stop_.load(); });
  }

  void discard_ring() {
    std::uint64_t head = head_.load(), tail = tail_.load();
    if (tail != head) bump(dropped_unsent_, tail - head);
    head_.store(tail, std::memory_order_release);
  }

  void send_ring() {
    while (fd_ >= 0) {
      const std::uint64_t head = head_.load(std::memory_order_relaxed);
      if (head == tail_.load(std::memory_order_acquire)) return;
      const std::string& cycle = slots_[head % slots_.size()];
      const std::uint64_t drops = dropped() - declared_;
      frame_.assign(4, '\0');
      frame_ += "{\"kind\":\"cycle\",\"seq\":";
      frame_ += std::to_string(seq_);
      frame_ += ",\"dropped\":";
      frame_ += std::to_string(std::min<std::uint64_t>(drops, 1'000'000));
      // Splice the client's object in after our fields: {"t_ns":...} -> ,"t_ns":...}
      if (cycle.size() > 2) frame_ += ',';
      frame_.append(cycle, 1, std::string::npos);
      head_.store(head + 1, std::memory_order_release);  // the slot is copied: free it
      if (!send_frame()) { bump(dropped_unsent_); return; }
      declared_ += std::min<std::uint64_t>(drops, 1'000'000);
      ++seq_;
      bump(sent_);
    }
  }

  bool send_frame() {
    const auto n = static_cast<std::uint32_t>(frame_.size() - 4);
    frame_[0] = static_cast<char>(n >> 24); frame_[1] = static_cast<char>(n >> 16);
    frame_[2] = static_cast<char>(n >> 8);  frame_[3] = static_cast<char>(n);
    std::size_t done = 0;
    while (done < frame_.size()) {
      ssize_t w = ::send(fd_, frame_.data() + done, frame_.size() - done, MSG_NOSIGNAL);
      if (w < 0 && errno == EINTR) continue;
      if (w <= 0) { disconnect(); return false; }  // a frame cut short: the stream is gone
      done += static_cast<std::size_t>(w);
    }
    return true;
  }

  bool connect_and_hello() {
    int fd = open_socket();
    if (fd < 0) return false;
    fd_ = fd;
    JsonWriter w(512);
    w.begin_object().key("kind").value("hello").key("protocol").value(kProtocolVersion)
        .key("robot_id").value(opt_.robot_id).key("period_ns").value(opt_.period_ns)
        .key("clock").value(opt_.clock).key("software_version").value(opt_.software_version)
        .key("policy_version").value(opt_.policy_version).key("profile").value(opt_.profile)
        .end_object();
    frame_.assign(4, '\0');
    frame_ += w.str();
    rx_.clear();
    if (!send_frame()) return false;
    const std::string kind = read_replies(static_cast<int>(opt_.connect_timeout.count()));
    if (kind != "welcome") {
      if (kind == "refused") refused_hello_.store(true);
      disconnect();
      return false;
    }
    bump(connects_);
    connected_.store(true, std::memory_order_release);
    return true;
  }

  int open_socket() {
    int fd;
    if (!opt_.socket_path.empty()) {
      sockaddr_un addr{};
      addr.sun_family = AF_UNIX;
      if (opt_.socket_path.size() >= sizeof addr.sun_path) return -1;
      std::memcpy(addr.sun_path, opt_.socket_path.c_str(), opt_.socket_path.size() + 1);
      fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
      if (fd < 0) return -1;
      if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) { ::close(fd); return -1; }
    } else {
      sockaddr_in addr{};
      addr.sin_family = AF_INET;
      addr.sin_port = htons(opt_.tcp_port);
      if (::inet_pton(AF_INET, opt_.tcp_host.c_str(), &addr.sin_addr) != 1) return -1;
      fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
      if (fd < 0) return -1;
      if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) { ::close(fd); return -1; }
      int one = 1;
      ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    }
    // A recorder that stops reading must not hold the sender forever: a send that cannot
    // finish within a second ends the connection (its frame would be cut anyway).
    timeval tv{1, 0};
    ::setsockopt(fd, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
    return fd;
  }

  // Read what the recorder sent, waiting up to wait_ms for the first byte; count errors.
  // Returns the kind of the last frame read (the recorder writes "kind" first).
  std::string read_replies(int wait_ms) {
    std::string last;
    auto until = Clock::now() + std::chrono::milliseconds(wait_ms);
    while (fd_ >= 0) {
      int left = static_cast<int>(std::chrono::duration_cast<std::chrono::milliseconds>(
                                      until - Clock::now()).count());
      pollfd p{fd_, POLLIN, 0};
      int ready = ::poll(&p, 1, last.empty() ? std::max(left, 0) : 0);
      if (ready < 0 && errno == EINTR) continue;
      if (ready <= 0) break;
      char buf[4096];
      ssize_t r = ::recv(fd_, buf, sizeof buf, 0);
      if (r < 0 && errno == EINTR) continue;
      if (r <= 0) { disconnect(); break; }  // the recorder went away
      rx_.append(buf, static_cast<std::size_t>(r));
      while (rx_.size() >= 4) {
        auto b = reinterpret_cast<const unsigned char*>(rx_.data());
        std::size_t n = (std::size_t(b[0]) << 24) | (std::size_t(b[1]) << 16) |
                        (std::size_t(b[2]) << 8) | b[3];
        if (n > kMaxFrameBytes) { disconnect(); return last; }
        if (rx_.size() < 4 + n) break;
        last = reply_kind(std::string_view(rx_).substr(4, n));
        rx_.erase(0, 4 + n);
      }
    }
    return last;
  }

  std::string reply_kind(std::string_view body) {
    constexpr std::string_view head = "{\"kind\":\"";
    if (body.substr(0, head.size()) != head) return "?";
    auto end = body.find('"', head.size());
    std::string kind(body.substr(head.size(), end - head.size()));
    if (kind == "error") bump(refused_);
    if (kind == "bye" && !stop_.load()) disconnect();  // the recorder is stopping: reconnect
    return kind;
  }

  void say_bye() {
    if (fd_ < 0) return;
    frame_.assign(4, '\0');
    frame_ += "{\"kind\":\"bye\"}";
    if (!send_frame()) return;
    while (fd_ >= 0 && Clock::now() < close_by_) {
      int left = static_cast<int>(std::chrono::duration_cast<std::chrono::milliseconds>(
                                      close_by_ - Clock::now()).count());
      if (read_replies(std::max(left, 1)) == "bye") break;
    }
  }

  void disconnect() {
    connected_.store(false, std::memory_order_release);
    if (fd_ >= 0) { ::close(fd_); fd_ = -1; }
  }

  Options opt_;
  std::vector<std::string> slots_;
  std::atomic<std::uint64_t> head_{0}, tail_{0};
  std::atomic<bool> connected_{false}, stop_{false}, refused_hello_{false};
  std::atomic<std::uint64_t> sent_{0}, refused_{0}, connects_{0};
  std::atomic<std::uint64_t> dropped_disconnected_{0}, dropped_full_{0}, dropped_invalid_{0};
  std::atomic<std::uint64_t> dropped_unsent_{0};
  std::uint64_t declared_ = 0, seq_ = 0;  // sender thread only
  std::mutex mu_;
  std::condition_variable wake_;
  Clock::time_point close_by_{};
  std::chrono::microseconds poll_{1000};
  std::string frame_, rx_;
  int fd_ = -1;
  std::thread sender_;
};

}  // namespace trace
