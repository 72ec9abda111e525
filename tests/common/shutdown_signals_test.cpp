// ShutdownSignals: which signals end a run in order, and that a closed pipe does not kill it.
// Hostile-input issue, row 9: `slamd ... 2>&1 | head -1`, SIGHUP and SIGUSR1 killed slamd (exit
// 141, 129, 138) before it wrote its outputs.

#include "slamd/common/shutdown_signals.hpp"

#include <signal.h>
#include <unistd.h>

#include <cerrno>

#include <gtest/gtest.h>

namespace slamd {
namespace {

TEST(ShutdownSignals, HangupAndUser1RequestAnOrderlyShutdown) {
  for (const int signal_number : {SIGHUP, SIGUSR1, SIGTERM}) {
    ShutdownSignals signals;
    ASSERT_EQ(kill(getpid(), signal_number), 0);
    EXPECT_TRUE(signals.waitFor(std::chrono::seconds(10))) << "signal " << signal_number;
    EXPECT_EQ(signals.signalNumber(), signal_number);
  }
}

TEST(ShutdownSignals, WritingToAClosedPipeFailsInsteadOfKillingTheProcess) {
  ShutdownSignals signals;
  int fds[2];
  ASSERT_EQ(pipe(fds), 0);
  close(fds[0]);
  errno = 0;
  EXPECT_EQ(write(fds[1], "x", 1), -1);
  EXPECT_EQ(errno, EPIPE);
  close(fds[1]);
  EXPECT_FALSE(signals.requested()) << "a broken pipe is not a shutdown request";
}

}  // namespace
}  // namespace slamd
