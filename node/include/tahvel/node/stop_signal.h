// How a program run by a supervisor (an agent, a link, a reasoner) ends on SIGTERM and SIGINT:
// it stops cleanly in both cases, and its exit status tells its supervisor whether that stop was
// asked for. A SIGTERM from its parent (the supervisor stopping it, `tahvel down` through the
// supervisor, a test harness) or a SIGINT (Ctrl-C) ends it with status 0. A SIGTERM from anyone
// else (an operator's `kill PID`) ends it with 143, 128 + SIGTERM, as a shell reports a process
// ended by it: ended with 0, the supervisor took it for finished and, under its default restart
// policy (on failure), never started it again.
#pragma once

namespace tahvel::node {

// Installs the handlers (without SA_RESTART: a blocking call returns with EINTR at the signal).
void install_stop_signal_handlers();

// Whether SIGTERM or SIGINT has arrived since install_stop_signal_handlers().
bool stop_signal_received();

// The exit status for a program ending now: 143 after a SIGTERM sent by a process other than
// its parent at the time the handlers were installed, else 0.
int stop_exit_status();

}  // namespace tahvel::node
