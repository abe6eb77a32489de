#include "rime/core/hash.h"

#include <xxhash.h>

#include <cstdio>
#include <fmt/format.h>
#include <memory>
#include <vector>

#include "rime/core/error.h"

namespace rime {

std::uint64_t Hash64(std::string_view bytes, std::uint64_t seed) { return XXH64(bytes.data(), bytes.size(), seed); }

std::uint64_t HashFile(const std::filesystem::path& path) {
  std::unique_ptr<FILE, int (*)(FILE*)> file(std::fopen(path.c_str(), "rb"), &std::fclose);
  if (!file) throw InputError("cannot open file for hashing", path.string());
  std::unique_ptr<XXH64_state_t, XXH_errorcode (*)(XXH64_state_t*)> state(XXH64_createState(), &XXH64_freeState);
  XXH64_reset(state.get(), 0);
  std::vector<char> buffer(1 << 20);
  std::size_t n;
  while ((n = std::fread(buffer.data(), 1, buffer.size(), file.get())) > 0) XXH64_update(state.get(), buffer.data(), n);
  if (std::ferror(file.get())) throw InputError("read error while hashing", path.string());
  return XXH64_digest(state.get());
}

std::string HexHash(std::uint64_t hash) { return fmt::format("{:016x}", hash); }

}  // namespace rime
