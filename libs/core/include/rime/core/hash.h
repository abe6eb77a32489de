/// @file hash.h
/// @brief Content hashes (xxHash64, hex) for file metadata and the pipeline's staleness checks.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

namespace rime {

std::uint64_t Hash64(std::string_view bytes, std::uint64_t seed = 0);
/// Hash of a file's content; throws rime::Error naming the file if it cannot be read.
std::uint64_t HashFile(const std::filesystem::path& path);
/// 16 lowercase hex digits.
std::string HexHash(std::uint64_t hash);

}  // namespace rime
