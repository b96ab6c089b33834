// LCM telemetry decoded by a separate process over udpm on the loopback (ttl=0): status fields arrive intact
// and the axis-state rate stays within its bound.
#include <chrono>
#include <cstdio>
#include <thread>

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include "daemon/telemetry.hpp"

namespace dm = scancell::daemon;
using namespace std::chrono_literals;

namespace {

struct Counts {
  int status = 0, axes = 0;
  long long last_job = 0;
  double last_measured = 0.0;
  char last_state[32] = {};
};

class Subscriber {
 public:
  void on_status(const lcm::ReceiveBuffer*, const std::string&, const scancell::status_t* m) {
    ++c.status;
    c.last_job = m->job_id;
    c.last_measured = m->measured_coverage;
    std::snprintf(c.last_state, sizeof c.last_state, "%s", m->job_state.c_str());
  }
  void on_axes(const lcm::ReceiveBuffer*, const std::string&, const scancell::axis_state_t* m) {
    if (m->n == 2 && m->name[1] == "lift") ++c.axes;
  }
  Counts c;
};

}  // namespace

TEST(Telemetry, AnotherProcessDecodesStatusAndTheAxisRateIsBounded) {
  // A port of its own: other tests (the daemon's) publish on the default group at the same time.
  const std::string url = "udpm://239.255.76.67:" + std::to_string(7700 + ::getpid() % 100) + "?ttl=0";
  int p[2];
  ASSERT_EQ(::pipe(p), 0);
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::close(p[0]);
    lcm::LCM lcm(url);
    Subscriber s;
    if (lcm.good()) {
      lcm.subscribe("SCANCELL_STATUS", &Subscriber::on_status, &s);
      lcm.subscribe("SCANCELL_AXIS_STATE", &Subscriber::on_axes, &s);
      const char ready = 'r';
      (void)!::write(p[1], &ready, 1);
      const auto end = std::chrono::steady_clock::now() + 2500ms;
      while (std::chrono::steady_clock::now() < end) lcm.handleTimeout(50);
    }
    (void)!::write(p[1], &s.c, sizeof s.c);
    ::_exit(0);
  }
  ::close(p[1]);
  char ready = 0;
  ASSERT_EQ(::read(p[0], &ready, 1), 1) << "the subscriber could not start LCM on " << url;
  std::this_thread::sleep_for(200ms);
  dm::Telemetry t(url, 20.0);
  for (int k = 0; k < 5; ++k) {
    scancell::status_t s{};
    s.daemon_state = "busy";
    s.job_id = 42;
    s.job_state = "executing";
    s.view = k + 1;
    s.views = 5;
    s.estimated_coverage = 0.99;
    s.measured_coverage = 0.2 * (k + 1);
    t.status(s);
    std::this_thread::sleep_for(20ms);
  }
  // A second of axis states offered as fast as possible: at most 20 Hz goes out.
  int published = 0;
  const auto end = std::chrono::steady_clock::now() + 1000ms;
  while (std::chrono::steady_clock::now() < end) {
    scancell::axis_state_t a{};
    a.name = {"reach", "lift"};
    a.position = {1.0, 2.0};
    a.moving = {true, false};
    a.fault = {0, 0};
    published += t.axes(a);
    std::this_thread::sleep_for(1ms);
  }
  Counts c;
  ASSERT_EQ(::read(p[0], &c, sizeof c), static_cast<ssize_t>(sizeof c));
  int status = 0;
  ::waitpid(pid, &status, 0);
  EXPECT_EQ(c.status, 5);
  EXPECT_EQ(c.last_job, 42);
  EXPECT_DOUBLE_EQ(c.last_measured, 1.0);
  EXPECT_STREQ(c.last_state, "executing");
  EXPECT_LE(published, 21);
  EXPECT_GE(published, 15);
  EXPECT_EQ(c.axes, published);
}
