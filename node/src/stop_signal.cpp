#include "tahvel/node/stop_signal.h"

#include <signal.h>
#include <unistd.h>

namespace tahvel::node {

namespace {

volatile sig_atomic_t g_stop = 0;
volatile sig_atomic_t g_stopped_from_elsewhere = 0;
// Read in the handler: set once, before the handlers are installed.
pid_t g_parent = 0;

void on_stop_signal(int signo, siginfo_t* info, void*) {
  g_stop = 1;
  if (signo == SIGTERM && info != nullptr && info->si_pid != g_parent) g_stopped_from_elsewhere = 1;
}

}  // namespace

void install_stop_signal_handlers() {
  g_parent = ::getppid();
  struct sigaction action {};
  action.sa_sigaction = on_stop_signal;
  action.sa_flags = SA_SIGINFO;
  sigemptyset(&action.sa_mask);
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
}

bool stop_signal_received() { return g_stop != 0; }

int stop_exit_status() { return g_stopped_from_elsewhere ? 128 + SIGTERM : 0; }

}  // namespace tahvel::node
