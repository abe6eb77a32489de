/// @file bake_outputs.h
/// @brief What the end-to-end tests compare and how they start rime-bake: a bake's files by
/// relative path (reports with their timings and output folder left out), and rime-bake started
/// with an argument vector so that no test value ever passes through a shell.
#pragma once

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "rime/test/files.h"

extern char** environ;

namespace rime::test {

/// Removes every field whose name holds "seconds" (wall times differ from run to run).
inline void DropTimings(nlohmann::json& value) {
  if (value.is_object()) {
    for (auto it = value.begin(); it != value.end();) {
      if (it.key().find("seconds") != std::string::npos) it = value.erase(it);
      else DropTimings(*it++);
    }
  } else if (value.is_array()) {
    for (auto& item : value) DropTimings(item);
  }
}

/// A temporary of rime/core/atomic_file.h: `<final>.tmp.<pid>.<n>`.
inline bool IsTemporary(const std::string& name) {
  const auto at = name.rfind(".tmp.");
  return at != std::string::npos && at > 0 && name.find_first_not_of("0123456789.", at + 5) == std::string::npos;
}

/// A file's bytes as the comparisons see them: reports (.json, .jsonl) record how long each step
/// took and where the output folder is, so those fields are left out (timings dropped, the folder
/// written as $OUT); every other byte counts.
inline std::string ComparableBytes(const std::filesystem::path& file, const std::filesystem::path& root) {
  std::string bytes = ReadFile(file);
  const std::string ext = file.extension().string();
  if (ext != ".json" && ext != ".jsonl") return bytes;
  std::vector<std::string> records = {bytes};
  if (ext == ".jsonl") {
    records.clear();
    std::istringstream lines(bytes);
    for (std::string line; std::getline(lines, line);) records.push_back(line);
  }
  bytes.clear();
  for (const auto& record : records) {
    nlohmann::json value = nlohmann::json::parse(record, nullptr, false);
    DropTimings(value);
    bytes += value.dump() + "\n";
  }
  for (std::size_t at; (at = bytes.find(root.string())) != std::string::npos;) bytes.replace(at, root.string().size(), "$OUT");
  return bytes;
}

/// Every file a bake leaves outside its own bookkeeping (state, logs), by path relative to `root`,
/// as ComparableBytes. Temporaries count too: a finished bake must not leave any.
inline std::map<std::string, std::string> Outputs(const std::filesystem::path& root) {
  std::map<std::string, std::string> files;
  for (const auto& entry : std::filesystem::recursive_directory_iterator(root)) {
    if (!entry.is_regular_file()) continue;
    const std::string name = entry.path().lexically_relative(root).generic_string();
    if (name.rfind("cache/.rime-bake/", 0) == 0 || name.rfind("cache/logs/", 0) == 0) continue;
    files[name] = ComparableBytes(entry.path(), root);
  }
  return files;
}

/// Files under final names, by relative path: what a bake has produced so far (no bookkeeping,
/// no temporaries).
inline std::set<std::string> FinalFiles(const std::filesystem::path& out) {
  std::set<std::string> names;
  std::error_code ec;
  for (std::filesystem::recursive_directory_iterator it(out, ec), end; !ec && it != end; it.increment(ec)) {
    if (!it->is_regular_file(ec)) continue;
    const std::string name = it->path().lexically_relative(out).generic_string();
    if (name.rfind("cache/.rime-bake/", 0) == 0 || name.rfind("cache/logs/", 0) == 0 || IsTemporary(name)) continue;
    names.insert(name);
  }
  return names;
}

/// Files under final names in `out` that are not complete, described one per line: each must be
/// byte-identical to the finished bake's (`reference`, from Outputs), except the two the
/// simulation rewrites after every frame: its stats (then a prefix of the finished ones) and its
/// sequence index (then a whole HDF5 file: its signature is checked).
inline std::vector<std::string> PartialFiles(const std::filesystem::path& out, const std::map<std::string, std::string>& reference) {
  std::vector<std::string> problems;
  for (const std::string& name : FinalFiles(out)) {
    const auto expected = reference.find(name);
    const std::string bytes = ComparableBytes(out / name, out);
    if (expected == reference.end()) problems.push_back(name + ": not made by the finished bake");
    else if (name == "cache/sim/stats.jsonl") {
      if (expected->second.rfind(bytes, 0) != 0) problems.push_back(name + ": not a prefix of the finished bake's");
    } else if (name == "cache/sim/particles.h5part") {
      if (bytes.substr(0, 8) != std::string("\x89HDF\r\n\x1a\n", 8)) problems.push_back(name + ": not an HDF5 file");
    } else if (bytes != expected->second) {
      problems.push_back(name + ": differs from the finished bake's (partial or damaged)");
    }
  }
  return problems;
}

/// Starts `args` (args[0]: the program) with stdout and stderr in `log`; returns its pid.
inline pid_t Spawn(const std::vector<std::string>& args, const std::filesystem::path& log) {
  std::vector<std::string> storage = args;
  std::vector<char*> argv;
  for (auto& a : storage) argv.push_back(a.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&actions, STDOUT_FILENO, STDERR_FILENO);
  pid_t pid = -1;
  if (posix_spawn(&pid, argv[0], &actions, nullptr, argv.data(), environ) != 0) pid = -1;
  posix_spawn_file_actions_destroy(&actions);
  return pid;
}

/// Waits for `pid`; returns its exit code, or 128 + signal.
inline int WaitExit(pid_t pid) {
  int status = 0;
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {}
  return WIFEXITED(status) ? WEXITSTATUS(status) : WIFSIGNALED(status) ? 128 + WTERMSIG(status) : -1;
}

/// Runs `args` to completion (see Spawn); returns its exit code and leaves its output in `output`.
inline int Run(const std::vector<std::string>& args, const std::filesystem::path& log, std::string& output) {
  const pid_t pid = Spawn(args, log);
  if (pid < 0) return -1;
  const int code = WaitExit(pid);
  output = ReadFile(log);
  return code;
}

}  // namespace rime::test
