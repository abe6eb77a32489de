/// @file memory.h
/// @brief Device arrays: plain allocations on the CPU or the GPU (no managed memory).
#pragma once

#include <algorithm>
#include <cstddef>
#include <span>
#include <utility>
#include <vector>

#include "rime/core/hd.h"
#include "rime/exec/device.h"

namespace rime::exec {

void* AllocateBytes(const Device& device, std::size_t bytes);
void FreeBytes(const Device& device, void* pointer);
/// Copies between host memory and the device (either side may be the CPU).
void CopyToDevice(const Device& device, void* device_dst, const void* host_src, std::size_t bytes);
void CopyToHost(const Device& device, void* host_dst, const void* device_src, std::size_t bytes);
void CopyOnDevice(const Device& device, void* dst, const void* src, std::size_t bytes);
void FillZero(const Device& device, void* pointer, std::size_t bytes);
/// Waits for all queued device work (no-op on the CPU).
void Synchronize(const Device& device);

/// An array that lives on one device for its whole life. Kernels get its raw pointer.
template <class T>
class DeviceArray {
 public:
  using value_type = T;
  DeviceArray() = default;
  explicit DeviceArray(const Device& device, std::size_t n = 0) : device_(device) { resize(n); }
  DeviceArray(const Device& device, const std::vector<T>& host) : device_(device) { assign(host); }
  ~DeviceArray() { release(); }
  DeviceArray(DeviceArray&& o) noexcept { swap(o); }
  DeviceArray& operator=(DeviceArray&& o) noexcept {
    swap(o);
    return *this;
  }
  DeviceArray(const DeviceArray&) = delete;
  DeviceArray& operator=(const DeviceArray&) = delete;

  T* data() { return data_; }
  const T* data() const { return data_; }
  std::size_t size() const { return size_; }
  bool empty() const { return size_ == 0; }
  const Device& device() const { return device_; }
  std::size_t bytes() const { return size_ * sizeof(T); }

  /// Resizes, keeping the first min(old, new) elements; new elements are zero.
  void resize(std::size_t n) {
    if (n > capacity_) reserve(std::max(n, capacity_ + capacity_ / 2));
    if (n > size_) FillZero(device_, data_ + size_, (n - size_) * sizeof(T));
    size_ = n;
  }
  /// Room for n elements without moving them again. The room beyond size() is not written (on the
  /// CPU its pages are not touched until resize() hands them out).
  void reserve(std::size_t n) {
    if (n <= capacity_) return;
    T* fresh = static_cast<T*>(AllocateBytes(device_, n * sizeof(T)));
    if (size_) CopyOnDevice(device_, fresh, data_, size_ * sizeof(T));
    FreeBytes(device_, data_);
    data_ = fresh;
    capacity_ = n;
  }
  void assign(const std::vector<T>& host) {
    resize(host.size());
    if (!host.empty()) CopyToDevice(device_, data_, host.data(), host.size() * sizeof(T));
  }
  std::vector<T> ToHost() const {
    std::vector<T> host(size_);
    if (size_) CopyToHost(device_, host.data(), data_, size_ * sizeof(T));
    return host;
  }
  void SetZero() { FillZero(device_, data_, size_ * sizeof(T)); }
  void release() {
    FreeBytes(device_, data_);
    data_ = nullptr;
    size_ = capacity_ = 0;
  }
  void swap(DeviceArray& o) noexcept {
    std::swap(device_, o.device_);
    std::swap(data_, o.data_);
    std::swap(size_, o.size_);
    std::swap(capacity_, o.capacity_);
  }

 private:
  Device device_;
  T* data_ = nullptr;
  std::size_t size_ = 0;
  std::size_t capacity_ = 0;
};

}  // namespace rime::exec
