#include "coordinator/core/node_check.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <sstream>

namespace demfdm::coord {

namespace {
bool executable_file(const std::string& p) {
  struct stat st {};
  return ::stat(p.c_str(), &st) == 0 && S_ISREG(st.st_mode) && ::access(p.c_str(), X_OK) == 0;
}

std::string trim(std::string s) {
  while (!s.empty() && (s.back() == '\n' || s.back() == ' ' || s.back() == '\r')) s.pop_back();
  std::size_t i = 0;
  while (i < s.size() && (s[i] == '\n' || s[i] == ' ')) ++i;
  return s.substr(i);
}
}  // namespace

std::string resolve_executable(const std::string& name, const std::string& bin_dir) {
  if (name.find('/') != std::string::npos) return executable_file(name) ? name : "";
  if (!bin_dir.empty() && executable_file(bin_dir + "/" + name)) return bin_dir + "/" + name;
  const char* path = std::getenv("PATH");
  std::stringstream ss(path ? path : "");
  for (std::string dir; std::getline(ss, dir, ':');)
    if (!dir.empty() && executable_file(dir + "/" + name)) return dir + "/" + name;
  return "";
}

std::string own_bin_dir() {
  char buf[4096];
  const ssize_t n = ::readlink("/proc/self/exe", buf, sizeof buf - 1);
  if (n <= 0) return "";
  std::string p(buf, static_cast<std::size_t>(n));
  const auto slash = p.rfind('/');
  return slash == std::string::npos ? "" : p.substr(0, slash);
}

std::optional<std::string> check_node(const std::string& exe, const std::string& scene,
                                      const std::vector<std::string>& sets) {
  std::vector<std::string> args{exe, "--check", scene};
  for (const auto& s : sets) {
    args.push_back("--set");
    args.push_back(s);
  }
  int fd[2];
  if (::pipe(fd) != 0) return std::string("cannot create a pipe: ") + std::strerror(errno);
  const pid_t pid = ::fork();
  if (pid < 0) return std::string("cannot start ") + exe + ": " + std::strerror(errno);
  if (pid == 0) {
    ::dup2(fd[1], 1);
    ::dup2(fd[1], 2);
    ::close(fd[0]);
    ::close(fd[1]);
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    ::execv(exe.c_str(), argv.data());
    std::fprintf(stderr, "cannot run %s: %s\n", exe.c_str(), std::strerror(errno));
    ::_exit(127);
  }
  ::close(fd[1]);
  std::string out;
  char buf[4096];
  for (ssize_t n; (n = ::read(fd[0], buf, sizeof buf)) != 0;) {
    if (n < 0) {
      if (errno == EINTR) continue;
      break;
    }
    out.append(buf, static_cast<std::size_t>(n));
  }
  ::close(fd[0]);
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  if (WIFEXITED(status) && WEXITSTATUS(status) == 0) return std::nullopt;
  out = trim(out);
  if (!out.empty()) return out;
  if (WIFSIGNALED(status)) return exe + " --check ended by signal " + std::to_string(WTERMSIG(status));
  return exe + " --check exited with code " + std::to_string(WEXITSTATUS(status)) + " and no message";
}

}  // namespace demfdm::coord
