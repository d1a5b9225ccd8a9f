// What the kernel says about another process of this machine: the agents of a node are
// processes, and an operator's command that waits on one (a remote query on the link, `down` on
// a supervisor) says why it will not answer rather than waiting out its timeout.
#pragma once

#include <sys/types.h>

#include <optional>

namespace tahvel::node {

// The state letter of process `pid` in /proc/PID/stat (proc(5): R running, S sleeping, D waiting
// in the kernel, T stopped by a signal, t stopped by a debugger, Z zombie, ...), or nullopt when
// there is no such process.
std::optional<char> process_state(pid_t pid);

// Stopped by a signal (SIGSTOP, SIGTSTP: 'kill -CONT PID' resumes it) or held by a debugger.
inline bool is_stopped(std::optional<char> state) { return state == 'T' || state == 't'; }

}  // namespace tahvel::node
