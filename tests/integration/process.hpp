// Small process helpers for integration tests: spawn real executables, wait with a deadline,
// kill, and enter a private network namespace (as root) so that udpm multicast stays inside.
#pragma once
#include <fcntl.h>
#include <sched.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace demfdm::testing {

struct Proc {
  pid_t pid = -1;
  std::string name;
};

// Starts argv[0] with the given arguments; extra_env as "K=V"; output appended to out_file.
inline Proc spawn(const std::vector<std::string>& argv, const std::vector<std::string>& extra_env = {},
                  const std::string& out_file = "/dev/null") {
  pid_t pid = fork();
  if (pid == 0) {
    int fd = ::open(out_file.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
    if (fd >= 0) {
      dup2(fd, 1);
      dup2(fd, 2);
    }
    for (auto& e : extra_env) putenv(const_cast<char*>(e.c_str()));
    std::vector<char*> a;
    for (auto& s : argv) a.push_back(const_cast<char*>(s.c_str()));
    a.push_back(nullptr);
    execv(a[0], a.data());
    _exit(127);
  }
  return {pid, argv[0]};
}

// Waits up to timeout_s; returns the wait status, or nullopt on timeout.
inline std::optional<int> wait_for(const Proc& p, double timeout_s) {
  auto t0 = std::chrono::steady_clock::now();
  for (;;) {
    int st = 0;
    pid_t r = waitpid(p.pid, &st, WNOHANG);
    if (r == p.pid) return st;
    if (std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() > timeout_s) return std::nullopt;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
}

inline void kill_and_reap(const Proc& p) {
  if (p.pid <= 0) return;
  ::kill(p.pid, SIGKILL);
  int st;
  waitpid(p.pid, &st, 0);
}

inline int exit_code(int status) { return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status); }

inline std::string read_file(const std::string& path) {
  std::ifstream f(path);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

// As root: a private network namespace with only 'lo', multicast on, 224.0.0.0/4 routed.
// Returns an empty string on success, else why udpm tests cannot run here.
inline std::string enter_private_network() {
  if (getenv("DEMFDM_IN_NETNS")) return "";  // launch/test already did it
  if (geteuid() != 0) return "not root: cannot create a private network namespace for udpm tests";
  if (unshare(CLONE_NEWNET) != 0) return "unshare(CLONE_NEWNET) failed";
  if (std::system("ip link set lo up && ip link set lo multicast on && ip route add 224.0.0.0/4 dev lo") != 0)
    return "could not configure lo in the private namespace (iproute2 missing?)";
  setenv("DEMFDM_IN_NETNS", "1", 1);
  return "";
}

}  // namespace demfdm::testing
