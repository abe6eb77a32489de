// CPU backend of the execution layer's algorithms (oneTBB). All results are independent of the
// number of threads: work is split into fixed-size blocks whose partial results are combined in
// block order.
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

#include "../cuda_backend.h"
#include "rime/exec/parallel.h"

namespace rime::exec {
namespace {

constexpr Index kBlock = 1 << 14;

Index BlockCount(Index n) { return (n + kBlock - 1) / kBlock; }

template <class Out, class T, class Op>
Out BlockReduce(const T* values, Index n, Out identity, Op op) {
  const Index blocks = BlockCount(n);
  std::vector<Out> partial(blocks, identity);
  tbb::parallel_for(Index(0), blocks, [&](Index b) {
    Out acc = identity;
    const Index end = std::min(n, (b + 1) * kBlock);
    for (Index i = b * kBlock; i < end; ++i) acc = op(acc, Out(values[i]));
    partial[b] = acc;
  });
  Out total = identity;
  for (const Out& p : partial) total = op(total, p);
  return total;
}

// Stable LSD radix sort with 8-bit digits; per-block histograms give a parallel, deterministic
// scatter.
void CpuSortPairs(std::uint64_t* keys, std::uint32_t* values, Index n, int key_bits) {
  if (n < 2) return;
  constexpr int kRadix = 256;
  constexpr Index kSortBlock = 1 << 15;
  std::vector<std::uint64_t> key_buffer(n);
  std::vector<std::uint32_t> value_buffer(n);
  std::uint64_t* key_src = keys;
  std::uint32_t* value_src = values;
  std::uint64_t* key_dst = key_buffer.data();
  std::uint32_t* value_dst = value_buffer.data();
  const Index blocks = (n + kSortBlock - 1) / kSortBlock;
  std::vector<std::array<Index, kRadix>> offsets(blocks);
  int passes = 0;
  for (int shift = 0; shift < key_bits; shift += 8, ++passes) {
    tbb::parallel_for(Index(0), blocks, [&](Index b) {
      auto& hist = offsets[b];
      hist.fill(0);
      const Index end = std::min(n, (b + 1) * kSortBlock);
      for (Index i = b * kSortBlock; i < end; ++i) ++hist[(key_src[i] >> shift) & 0xff];
    });
    Index running = 0;
    for (int digit = 0; digit < kRadix; ++digit)
      for (Index b = 0; b < blocks; ++b) {
        const Index count = offsets[b][digit];
        offsets[b][digit] = running;
        running += count;
      }
    tbb::parallel_for(Index(0), blocks, [&](Index b) {
      auto& offset = offsets[b];
      const Index end = std::min(n, (b + 1) * kSortBlock);
      for (Index i = b * kSortBlock; i < end; ++i) {
        const Index dst = offset[(key_src[i] >> shift) & 0xff]++;
        key_dst[dst] = key_src[i];
        value_dst[dst] = value_src[i];
      }
    });
    std::swap(key_src, key_dst);
    std::swap(value_src, value_dst);
  }
  if (passes % 2 == 1) {
    std::copy(key_src, key_src + n, keys);
    std::copy(value_src, value_src + n, values);
  }
}

std::uint64_t CpuExclusiveScan(const std::uint32_t* in, std::uint32_t* out, Index n) {
  if (n == 0) return 0;
  const Index blocks = BlockCount(n);
  std::vector<std::uint64_t> block_sums(blocks + 1, 0);
  tbb::parallel_for(Index(0), blocks, [&](Index b) {
    std::uint64_t s = 0;
    const Index end = std::min(n, (b + 1) * kBlock);
    for (Index i = b * kBlock; i < end; ++i) s += in[i];
    block_sums[b + 1] = s;
  });
  for (Index b = 0; b < blocks; ++b) block_sums[b + 1] += block_sums[b];
  tbb::parallel_for(Index(0), blocks, [&](Index b) {
    std::uint64_t s = block_sums[b];
    const Index end = std::min(n, (b + 1) * kBlock);
    for (Index i = b * kBlock; i < end; ++i) {
      const std::uint32_t v = in[i];
      out[i] = static_cast<std::uint32_t>(s);
      s += v;
    }
  });
  return block_sums[blocks];
}

template <class T>
T MaxOp(T a, T b) {
  // NaN propagates so divergence checks see it.
  if (std::isnan(a) || std::isnan(b)) return std::numeric_limits<T>::quiet_NaN();
  return a > b ? a : b;
}

}  // namespace

void SortPairs(const Device& device, std::uint64_t* keys, std::uint32_t* values, Index n, int key_bits) {
  key_bits = std::clamp(key_bits, 1, 64);
  if (device.is_cuda()) cuda_impl::SortPairs(keys, values, n, key_bits);
  else CpuSortPairs(keys, values, n, key_bits);
}

std::uint64_t ExclusiveScan(const Device& device, const std::uint32_t* in, std::uint32_t* out, Index n) {
  return device.is_cuda() ? cuda_impl::ExclusiveScan(in, out, n) : CpuExclusiveScan(in, out, n);
}

double Sum(const Device& device, const float* v, Index n) {
  return device.is_cuda() ? cuda_impl::Sum(v, n) : BlockReduce<double>(v, n, 0.0, [](double a, double b) { return a + b; });
}
double Sum(const Device& device, const double* v, Index n) {
  return device.is_cuda() ? cuda_impl::Sum(v, n) : BlockReduce<double>(v, n, 0.0, [](double a, double b) { return a + b; });
}
float Max(const Device& device, const float* v, Index n) {
  return device.is_cuda() ? cuda_impl::Max(v, n) : BlockReduce<float>(v, n, -INFINITY, MaxOp<float>);
}
double Max(const Device& device, const double* v, Index n) {
  return device.is_cuda() ? cuda_impl::Max(v, n) : BlockReduce<double>(v, n, -INFINITY, MaxOp<double>);
}

}  // namespace rime::exec
