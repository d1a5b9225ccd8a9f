// How a program that installs the stop handlers ends on SIGTERM (node/stop_signal.h): cleanly
// in both cases, with 0 when its parent stopped it and 143 when someone else did.
#include "tahvel/node/stop_signal.h"

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <thread>

namespace tahvel::node {
namespace {

// Forks a program that installs the handlers, says it is ready on a pipe, and ends with
// stop_exit_status() once a stop signal arrived; returns its pid once it is ready (-1: not
// started).
pid_t start_program() {
  int ready[2];
  if (pipe(ready) != 0) return -1;
  const pid_t pid = fork();
  if (pid == 0) {
    close(ready[0]);
    install_stop_signal_handlers();
    (void)!write(ready[1], "r", 1);
    while (!stop_signal_received()) std::this_thread::sleep_for(std::chrono::milliseconds(5));
    _exit(stop_exit_status());
  }
  close(ready[1]);
  char c;
  (void)!read(ready[0], &c, 1);
  close(ready[0]);
  return pid;
}

int exit_status_of(pid_t pid) {
  int status = 0;
  if (waitpid(pid, &status, 0) != pid) return -1;
  return WIFEXITED(status) ? WEXITSTATUS(status) : 1000 + WTERMSIG(status);
}

// Sends `sig` to `pid` from a process that is not its parent (a sibling, as an operator's shell
// is); true when it was sent.
bool signal_from_another_process(pid_t pid, int sig) {
  const pid_t other = fork();
  if (other == 0) _exit(kill(pid, sig) == 0 ? 0 : 1);
  return other > 0 && exit_status_of(other) == 0;
}

// Its supervisor (the parent) stops it: a finish, 0.
TEST(StopSignal, ASigtermFromTheParentEndsTheProgramWithZero) {
  const pid_t pid = start_program();
  ASSERT_GT(pid, 0);
  ASSERT_EQ(kill(pid, SIGTERM), 0);
  EXPECT_EQ(exit_status_of(pid), 0);
}

// An operator's `kill PID` (another process): 143, which a supervisor restarting on failure
// restarts. It ended with 0 and was taken for finished.
TEST(StopSignal, ASigtermFromAnotherProcessEndsTheProgramWith143) {
  const pid_t pid = start_program();
  ASSERT_GT(pid, 0);
  ASSERT_TRUE(signal_from_another_process(pid, SIGTERM));
  EXPECT_EQ(exit_status_of(pid), 128 + SIGTERM);
}

// Ctrl-C at a terminal (SIGINT, from the kernel): a finish, 0.
TEST(StopSignal, ASigintEndsTheProgramWithZero) {
  const pid_t pid = start_program();
  ASSERT_GT(pid, 0);
  ASSERT_TRUE(signal_from_another_process(pid, SIGINT));
  EXPECT_EQ(exit_status_of(pid), 0);
}

}  // namespace
}  // namespace tahvel::node
