/// @file local_slurm.h
/// @brief A single-node Slurm cluster on localhost for the farm test and benchmark: Debian's
/// slurmctld and slurmd with a generated slurm.conf (auth/none, ports above 1024, every path in a
/// folder of its own), run as children that die with the process that started them.
#pragma once

#include <netinet/in.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fmt/format.h>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace rime::test {

class LocalSlurm {
 public:
  /// Where slurmctld/slurmd and the client commands are; nullopt when Slurm is not installed.
  static std::optional<std::string> MissingBinary() {
    for (const char* name : {"slurmctld", "slurmd", "slurmstepd"})
      if (!Find(name, {"/usr/sbin", "/usr/local/sbin", "/usr/bin"})) return std::string(name);
    for (const char* name : {"sbatch", "squeue", "scancel", "scontrol", "sinfo"})
      if (!Find(name, {"/usr/bin", "/usr/local/bin"})) return std::string(name);
    return std::nullopt;
  }

  ~LocalSlurm() { Stop(); }

  /// Writes slurm.conf under `folder`, starts both daemons and waits (at most `timeout`) for the
  /// node to be idle. Sets SLURM_CONF for this process and its children. Empty string on success,
  /// else what went wrong.
  std::string Start(const std::filesystem::path& folder, std::chrono::seconds timeout = std::chrono::seconds(60)) {
    namespace fs = std::filesystem;
    folder_ = folder;
    fs::create_directories(folder / "state");
    fs::create_directories(folder / "spool");
    const int port = FreePortPair();
    const unsigned cpus = std::max(2u, std::thread::hardware_concurrency());
    std::string user = "root";
    if (const char* u = std::getenv("USER"); u && *u) user = u;
    if (getuid() == 0) user = "root";
    std::ofstream(folder / "slurm.conf") << fmt::format(
        "ClusterName=rimetest\nSlurmctldHost=localhost\nSlurmUser={user}\nSlurmdUser={user}\n"
        "SlurmctldPort={p0}\nSlurmdPort={p1}\nAuthType=auth/none\nCredType=cred/none\n"
        "StateSaveLocation={d}/state\nSlurmdSpoolDir={d}/spool\nSlurmctldPidFile={d}/slurmctld.pid\nSlurmdPidFile={d}/slurmd.pid\n"
        "SlurmctldLogFile={d}/slurmctld.log\nSlurmdLogFile={d}/slurmd.log\n"
        "ProctrackType=proctrack/linuxproc\nTaskPlugin=task/none\nSelectType=select/cons_tres\nSelectTypeParameters=CR_Core\n"
        "AccountingStorageType=accounting_storage/none\nJobCompType=jobcomp/filetxt\nJobCompLoc={d}/jobcomp.txt\n"
        "SchedulerParameters=batch_sched_delay=0,sched_interval=2\nDependencyParameters=kill_invalid_depend\n"
        "SlurmdParameters=config_overrides\nMailProg=/bin/true\nReturnToService=2\nMinJobAge=600\nKillWait=5\n"
        "NodeName=localhost NodeAddr=127.0.0.1 CPUs={cpus} Sockets=1 CoresPerSocket={cpus} ThreadsPerCore=1 State=UNKNOWN\n"
        "PartitionName=rime Nodes=localhost Default=YES MaxTime=INFINITE State=UP\n",
        fmt::arg("user", user), fmt::arg("p0", port), fmt::arg("p1", port + 1), fmt::arg("d", folder.string()), fmt::arg("cpus", cpus));
    setenv("SLURM_CONF", (folder / "slurm.conf").c_str(), 1);
    const std::string conf = (folder / "slurm.conf").string();
    ctld_ = Spawn({*Find("slurmctld", {"/usr/sbin", "/usr/local/sbin"}), "-D", "-i", "-f", conf}, folder / "slurmctld.out");
    slurmd_ = Spawn({*Find("slurmd", {"/usr/sbin", "/usr/local/sbin"}), "-D", "-f", conf, "-N", "localhost"}, folder / "slurmd.out");
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < deadline) {
      const std::string state = Capture("sinfo --noheader --format=%T 2>/dev/null");
      if (state.rfind("idle", 0) == 0) return "";
      for (pid_t pid : {ctld_, slurmd_})
        if (pid > 0 && waitpid(pid, nullptr, WNOHANG) == pid) {
          (pid == ctld_ ? ctld_ : slurmd_) = -1;
          return fmt::format("a Slurm daemon exited at start; see {}", folder.string());
        }
      std::this_thread::sleep_for(std::chrono::milliseconds(200));
    }
    return fmt::format("the localhost node did not become idle within {} s; see {}/slurmctld.log and slurmd.log", timeout.count(),
                       folder.string());
  }

  /// Cancels every job of this private cluster and waits (at most 30 s) for the queue to empty, so
  /// that no job step outlives it; then `scontrol shutdown`, and kills daemons still there 10 s later.
  void Stop() {
    if (ctld_ <= 0 && slurmd_ <= 0) return;
    [[maybe_unused]] int ignored = std::system("scancel --me >/dev/null 2>&1");
    const auto drained = std::chrono::steady_clock::now() + std::chrono::seconds(30);
    while (std::chrono::steady_clock::now() < drained && !Capture("squeue --noheader 2>/dev/null").empty())
      std::this_thread::sleep_for(std::chrono::milliseconds(200));
    ignored = std::system("scontrol shutdown >/dev/null 2>&1");
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    for (pid_t* pid : {&ctld_, &slurmd_}) {
      while (*pid > 0 && std::chrono::steady_clock::now() < deadline) {
        if (waitpid(*pid, nullptr, WNOHANG) == *pid) *pid = -1;
        else std::this_thread::sleep_for(std::chrono::milliseconds(100));
      }
      if (*pid > 0) {
        kill(*pid, SIGKILL);
        waitpid(*pid, nullptr, 0);
        *pid = -1;
      }
    }
  }

  /// Output of a shell command (the test's own fixed commands, never scene values).
  static std::string Capture(const std::string& command) {
    std::string out;
    if (FILE* pipe = popen(command.c_str(), "r")) {
      char buffer[4096];
      while (const std::size_t n = fread(buffer, 1, sizeof buffer, pipe)) out.append(buffer, n);
      pclose(pipe);
    }
    return out;
  }

 private:
  static std::optional<std::string> Find(const std::string& name, std::vector<std::string> folders) {
    if (const char* path = std::getenv("PATH")) {
      std::stringstream parts(path);
      for (std::string part; std::getline(parts, part, ':');) folders.push_back(part);
    }
    for (const auto& folder : folders) {
      const std::string candidate = folder + "/" + name;
      if (access(candidate.c_str(), X_OK) == 0) return candidate;
    }
    return std::nullopt;
  }

  // Two consecutive free TCP ports above 1024 on the loopback address.
  static int FreePortPair() {
    for (int attempt = 0; attempt < 200; ++attempt) {
      const int port = 20000 + (getpid() * 7 + attempt * 131) % 30000;
      bool free = true;
      for (int p : {port, port + 1}) {
        const int fd = socket(AF_INET, SOCK_STREAM, 0);
        sockaddr_in address{};
        address.sin_family = AF_INET;
        address.sin_port = htons(static_cast<std::uint16_t>(p));
        address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
        free = free && bind(fd, reinterpret_cast<sockaddr*>(&address), sizeof address) == 0;
        close(fd);
      }
      if (free) return port;
    }
    return 26817;
  }

  // Runs a daemon in the foreground as a child that gets SIGTERM when this process dies.
  static pid_t Spawn(const std::vector<std::string>& argv, const std::filesystem::path& log) {
    const pid_t parent = getpid();
    const pid_t pid = fork();
    if (pid != 0) return pid;
    prctl(PR_SET_PDEATHSIG, SIGTERM);
    if (getppid() != parent) _exit(1);
    std::FILE* out = std::fopen(log.c_str(), "w");
    if (out) {
      dup2(fileno(out), STDOUT_FILENO);
      dup2(fileno(out), STDERR_FILENO);
    }
    std::vector<char*> args;
    for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
    args.push_back(nullptr);
    execv(args[0], args.data());
    _exit(127);
  }

  std::filesystem::path folder_;
  pid_t ctld_ = -1, slurmd_ = -1;
};

}  // namespace rime::test
