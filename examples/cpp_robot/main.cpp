// cpp_robot: a warehouse robot's control loop in C++ that keeps a TRACE audit trail through
// trace-recorder (clients/cpp/trace_client.hpp; the protocol is schemas/PROFILE.md section 13).
//
//   trace-recorder serve --root logs --socket /tmp/trace.sock &
//   cpp_robot --socket /tmp/trace.sock --robot-id amr-cpp --cycles 500 --hz 50
//   trace-audit verify logs
//
// Each cycle the robot reads a range sensor, sees an obstacle, derives its distance and
// collision risk, and chooses STOP (nearer than 2 m), SLOW (nearer than 4 m) or CONTINUE;
// the four layers and the reading go to the recorder as one JSON object. Every tenth cycle
// the link from the obstacle to its reading is lost (ref null), and every thirteenth the
// alternatives are not logged, so an investigator's metrics have something to find. The
// quantities are integers (millimetres) divided once, so a Python twin computes the same
// doubles (tests/trace_runtime/recorder/warehouse.py).
//
// The last line of output is `sent N dropped D max_us X p99_us Y`: what the recorder was
// sent, what was dropped, and the control thread's own cost per cycle (building the JSON
// and handing it to the client), measured with steady_clock.
#include "trace_client.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

namespace {

struct Args {
  trace::Options client;
  long cycles = 100;
  double hz = 10.0;
  bool sim_time = false;
  bool announce = false;
  int beams = 0;
};

[[noreturn]] void usage(const char* why) {
  std::fprintf(stderr,
               "cpp_robot: %s\nusage: cpp_robot (--socket PATH | --tcp HOST:PORT) --robot-id ID "
               "[--cycles N] [--hz F] [--sim-time] [--beams K] [--announce]\n",
               why);
  std::exit(2);
}

Args parse(int argc, char** argv) {
  Args a;
  for (int i = 1; i < argc; ++i) {
    std::string k = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) usage(("missing value for " + k).c_str());
      return argv[++i];
    };
    if (k == "--socket") a.client.socket_path = next();
    else if (k == "--tcp") {
      std::string v = next();
      auto colon = v.rfind(':');
      if (colon == std::string::npos) usage("--tcp needs HOST:PORT");
      a.client.tcp_host = v.substr(0, colon);
      a.client.tcp_port = static_cast<std::uint16_t>(std::atoi(v.c_str() + colon + 1));
    } else if (k == "--robot-id") a.client.robot_id = next();
    else if (k == "--cycles") a.cycles = std::atol(next().c_str());
    else if (k == "--hz") a.hz = std::atof(next().c_str());
    else if (k == "--beams") a.beams = std::atoi(next().c_str());
    else if (k == "--sim-time") a.sim_time = true;
    else if (k == "--announce") a.announce = true;
    else usage(("unknown option " + k).c_str());
  }
  if (a.client.socket_path.empty() && a.client.tcp_host.empty()) usage("give --socket or --tcp");
  if (a.client.robot_id.empty()) usage("give --robot-id");
  if (!(a.hz > 0) || a.cycles < 0 || a.beams < 0) usage("--hz must be positive, --cycles and --beams not negative");
  a.client.period_ns = static_cast<std::int64_t>(1e9 / a.hz + 0.5);
  a.client.clock = a.sim_time ? "sim" : "system";
  a.client.software_version = "cpp_robot 1.0";
  a.client.policy_version = "stop-slow-continue";
  return a;
}

const char* const kCommands[] = {"STOP", "SLOW", "CONTINUE"};
const long kTargetMmS[] = {0, 400, 1000};

// One cycle of the policy as JSON. `actual_mm_s` carries the actuator's lag between cycles.
void build_cycle(trace::JsonWriter& w, long i, std::int64_t t_ns, int beams, long& actual_mm_s) {
  const long d_mm = 1000 + 100 * std::labs(i % 90 - 45);  // an obstacle comes and goes
  const double d = d_mm / 1000.0;
  const int choice = d_mm < 2000 ? 0 : d_mm < 4000 ? 1 : 2;
  const long target = kTargetMmS[choice];
  actual_mm_s += (target - actual_mm_s) * 6 / 10;  // C++ division truncates towards zero
  w.clear();
  w.begin_object().key("t_ns").value(t_ns);
  w.key("sensors").begin_array();
  w.begin_object().key("topic").value("/sensors/range").key("data").begin_object()
      .key("range_m").value(d).end_object().key("log_time_ns").value(t_ns).end_object();
  if (beams > 0) {
    w.begin_object().key("topic").value("/sensors/scan").key("data").begin_object().key("ranges").begin_array();
    for (int j = 0; j < beams; ++j) w.value((1000 + (i * 7 + j * 13) % 9000) / 1000.0);
    w.end_array().end_object().key("log_time_ns").value(t_ns).end_object();
  }
  w.end_array();

  w.key("perception").begin_object().key("entities").begin_array().begin_object()
      .key("id").value("obstacle_1").key("class").value("person")
      .key("pose").begin_object().key("position").begin_array().value(d).value(0.0).value(0.0).end_array().end_object()
      .key("confidence").begin_object().key("person").value(0.9).key("pallet").value(0.1).end_object()
      .key("evidence").begin_array().begin_object().key("sensor").value("range").key("weight").value(1.0).key("ref");
  if (i % 10 == 7) w.null();  // the link to the reading was lost
  else w.begin_object().key("topic").value("/sensors/range").key("log_time_ns").value(t_ns).end_object();
  w.end_object().end_array().end_object().end_array()
      .key("sensors_used").begin_array().value("range").end_array().end_object();

  w.key("belief").begin_object().key("nodes").begin_array()
      .begin_object().key("id").value("obstacle_1").key("kind").value("entity").key("p").value(0.9).key("entity").value("obstacle_1").end_object()
      .begin_object().key("id").value("obstacle_1.distance").key("kind").value("state").key("p").value(0.95).key("value").value(d).key("unit").value("m").end_object()
      .begin_object().key("id").value("obstacle_1.risk").key("kind").value("state").key("p").value(0.9).key("value").value(std::min(1000L, 1400000L / d_mm) / 1000.0).end_object()
      .end_array().key("edges").begin_array()
      .begin_object().key("parent").value("obstacle_1").key("child").value("obstacle_1.distance").key("p").value(0.95).key("rule").value("range_to_distance").end_object()
      .begin_object().key("parent").value("obstacle_1.distance").key("child").value("obstacle_1.risk").key("p").value(0.9).key("rule").value("risk_from_distance").end_object()
      .end_array().end_object();

  w.key("action").begin_object().key("command").value(kCommands[choice]).key("alternatives").begin_array();
  if (i % 13 != 5) {  // every thirteenth cycle the alternatives are not logged
    for (int c = 0; c < 3; ++c)
      if (c != choice)
        w.begin_object().key("command").value(kCommands[c]).key("score").value(0.0)
            .key("rejected_because").value("policy threshold").end_object();
  }
  char text[48];
  std::snprintf(text, sizeof text, "obstacle at %ld mm", d_mm);
  w.end_array().key("rationale").begin_object().key("text").value(text).key("factors").begin_array()
      .begin_object().key("node").value("obstacle_1.distance").key("name").value("distance")
      .key("value").value(d).key("unit").value("m").end_object().end_array().end_object();
  w.key("counterfactuals").begin_array();
  auto cf = [&](const char* cmp, double threshold, const char* would) {
    w.begin_object().key("factor").value("obstacle_1.distance").key("comparison").value(cmp)
        .key("threshold").value(threshold).key("would_select").value(would).end_object();
  };
  if (choice == 0) cf(">=", 2.0, "SLOW");
  if (choice == 1) { cf("<", 2.0, "STOP"); cf(">=", 4.0, "CONTINUE"); }
  if (choice == 2) cf("<", 4.0, "SLOW");
  w.end_array().end_object();

  w.key("execution").begin_object()
      .key("intended").begin_object().key("linear").value(target / 1000.0).end_object()
      .key("actual").begin_object().key("linear").value(actual_mm_s / 1000.0).end_object()
      .key("deviation").value(std::labs(target - actual_mm_s) / 1000.0).end_object();
  w.end_object();
}

double percentile_us(std::vector<std::int64_t> ns, double q) {
  if (ns.empty()) return 0.0;
  std::sort(ns.begin(), ns.end());
  std::size_t k = static_cast<std::size_t>(q * static_cast<double>(ns.size() - 1) + 0.5);
  return static_cast<double>(ns[k]) / 1000.0;
}

}  // namespace

int main(int argc, char** argv) {
  Args args = parse(argc, argv);
  trace::Client client(args.client);
  if (!client.wait_connected(std::chrono::seconds(3)))
    std::fprintf(stderr, "cpp_robot: no recorder yet; cycles are dropped until it answers\n");
  trace::JsonWriter w(16 * 1024 + static_cast<std::size_t>(args.beams) * 8);
  std::vector<std::int64_t> cost_ns, send_ns;
  cost_ns.reserve(static_cast<std::size_t>(args.cycles));
  send_ns.reserve(static_cast<std::size_t>(args.cycles));
  const auto period = std::chrono::nanoseconds(args.client.period_ns);
  const auto start = std::chrono::steady_clock::now();
  long actual_mm_s = 1000;
  std::size_t bytes = 0;
  for (long i = 0; i < args.cycles; ++i) {
    std::this_thread::sleep_until(start + i * period);
    const std::int64_t t_ns = args.sim_time
        ? i * args.client.period_ns
        : std::chrono::duration_cast<std::chrono::nanoseconds>(
              std::chrono::system_clock::now().time_since_epoch()).count();
    const auto t0 = std::chrono::steady_clock::now();
    build_cycle(w, i, t_ns, args.beams, actual_mm_s);
    const auto t1 = std::chrono::steady_clock::now();
    client.send_cycle(w.str());
    const auto t2 = std::chrono::steady_clock::now();
    cost_ns.push_back(std::chrono::duration_cast<std::chrono::nanoseconds>(t2 - t0).count());
    send_ns.push_back(std::chrono::duration_cast<std::chrono::nanoseconds>(t2 - t1).count());
    bytes = w.str().size();
    if (args.announce) std::printf("cycle %ld\n", i), std::fflush(stdout);
  }
  client.close();
  std::printf("cycle_bytes %zu send_p50_us %.3f send_p99_us %.3f send_max_us %.3f p50_us %.3f\n",
              bytes, percentile_us(send_ns, 0.5), percentile_us(send_ns, 0.99),
              percentile_us(send_ns, 1.0), percentile_us(cost_ns, 0.5));
  std::printf("sent %llu dropped %llu max_us %.3f p99_us %.3f\n",
              static_cast<unsigned long long>(client.sent()),
              static_cast<unsigned long long>(client.dropped()), percentile_us(cost_ns, 1.0),
              percentile_us(cost_ns, 0.99));
  return 0;
}
