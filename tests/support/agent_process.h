// An agent program run as a child process by a test: started with execv, stopped with SIGTERM
// (SIGKILL after 20 s) when destroyed. Shared by the tests that run the HRV and trend agents.
#pragma once

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <string>
#include <vector>

namespace tahvel::test_support {

class AgentProcess {
 public:
  // With `stderr_path`, the program's stderr is appended to that file.
  explicit AgentProcess(std::vector<std::string> argv, const std::string& stderr_path = "") {
    pid_ = fork();
    if (pid_ == 0) {
      if (!stderr_path.empty()) {
        const int fd = open(stderr_path.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
        if (fd < 0 || dup2(fd, 2) < 0) _exit(126);
        close(fd);
      }
      std::vector<char*> args;
      for (auto& a : argv) args.push_back(a.data());
      args.push_back(nullptr);
      execv(args[0], args.data());
      _exit(127);
    }
  }
  AgentProcess(const AgentProcess&) = delete;
  AgentProcess& operator=(const AgentProcess&) = delete;
  ~AgentProcess() { stop(); }

  // The exit status once it ended (128 + signal when killed), or -1 while it runs.
  int poll() {
    if (status_ < 0 && pid_ > 0) {
      int s = 0;
      if (waitpid(pid_, &s, WNOHANG) == pid_) status_ = WIFEXITED(s) ? WEXITSTATUS(s) : 128 + WTERMSIG(s);
    }
    return status_;
  }

  // SIGKILL: a crash, with no chance to finish the current item.
  void crash() {
    if (pid_ > 0 && poll() < 0) kill(pid_, SIGKILL);
    while (pid_ > 0 && poll() < 0) usleep(1000);
  }

  // SIGTERM, then waits for the exit status (SIGKILL after 20 s).
  int stop() {
    if (pid_ <= 0 || poll() >= 0) return status_;
    kill(pid_, SIGTERM);
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
    while (poll() < 0) {
      if (std::chrono::steady_clock::now() > deadline) kill(pid_, SIGKILL);
      usleep(10000);  // reaping a child has no wake-up to wait on; bounded by the deadline
    }
    return status_;
  }

  // Waits for the program to exit by itself, at most `limit`; then stops it.
  int wait(std::chrono::seconds limit) {
    const auto deadline = std::chrono::steady_clock::now() + limit;
    while (poll() < 0 && std::chrono::steady_clock::now() < deadline) usleep(10000);
    return poll() >= 0 ? status_ : stop();
  }

 private:
  pid_t pid_ = -1;
  int status_ = -1;
};

}  // namespace tahvel::test_support
