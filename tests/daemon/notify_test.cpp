// sd_notify messages reach a NOTIFY_SOCKET like systemd's, and the watchdog period is read from the
// environment systemd sets (WATCHDOG_USEC, WATCHDOG_PID).
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>

#include <gtest/gtest.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include "daemon/notify.hpp"

namespace dm = scancell::daemon;

TEST(Notify, ReadyStatusAndWatchdogReachTheNotifySocket) {
  const std::string path = (std::filesystem::temp_directory_path() / ("scancell-notify-" + std::to_string(::getpid()))).string();
  const int fd = ::socket(AF_UNIX, SOCK_DGRAM, 0);
  ASSERT_GE(fd, 0);
  sockaddr_un a{};
  a.sun_family = AF_UNIX;
  std::memcpy(a.sun_path, path.c_str(), path.size() + 1);
  ::unlink(path.c_str());
  ASSERT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
  ::setenv("NOTIFY_SOCKET", path.c_str(), 1);
  ::setenv("WATCHDOG_USEC", "2000000", 1);
  ::setenv("WATCHDOG_PID", std::to_string(::getpid()).c_str(), 1);
  dm::ServiceNotifier n;
  EXPECT_TRUE(n.under_systemd());
  EXPECT_EQ(n.watchdog_period().count(), 2000000);
  auto next = [&] {
    char buf[512] = {};
    const ssize_t r = ::recv(fd, buf, sizeof buf - 1, 0);
    return std::string(buf, r > 0 ? static_cast<std::size_t>(r) : 0);
  };
  EXPECT_TRUE(n.ready("idle, 0 jobs"));
  EXPECT_EQ(next(), "READY=1\nSTATUS=idle, 0 jobs");
  EXPECT_TRUE(n.watchdog());
  EXPECT_EQ(next(), "WATCHDOG=1");
  EXPECT_TRUE(n.stopping("parking axes"));
  EXPECT_EQ(next(), "STOPPING=1\nSTATUS=parking axes");
  ::unsetenv("NOTIFY_SOCKET");
  ::unsetenv("WATCHDOG_USEC");
  ::unsetenv("WATCHDOG_PID");
  dm::ServiceNotifier plain;
  EXPECT_FALSE(plain.under_systemd());
  EXPECT_FALSE(plain.ready("x"));  // a no-op outside systemd
  ::close(fd);
  ::unlink(path.c_str());
}
