#pragma once
// What the CUDA translation units of compensation/ share: errors as std::runtime_error naming
// the call, and device memory owned by one object. Included by .cu files only.
#include <algorithm>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <cuda_runtime.h>

namespace procam::cuda {

[[noreturn]] inline void Throw(const char* call, const std::string& what) {
  throw std::runtime_error(std::string("CUDA: ") + call + " failed: " + what);
}
inline void Check(cudaError_t status, const char* call) {
  if (status != cudaSuccess) Throw(call, cudaGetErrorString(status));
}
#define PROCAM_CUDA(call) Check((call), #call)
// After a kernel launch.
#define PROCAM_CUDA_LAUNCHED(name) Check(cudaGetLastError(), name)

// Device memory owned by one object; at least one element, so that an empty part still has a
// valid pointer.
template <typename T>
class DeviceArray {
 public:
  DeviceArray() = default;
  explicit DeviceArray(size_t count) : count_(count) {
    PROCAM_CUDA(cudaMalloc(reinterpret_cast<void**>(&data_), std::max<size_t>(count, 1) * sizeof(T)));
  }
  ~DeviceArray() {
    if (data_ != nullptr) cudaFree(data_);
  }
  DeviceArray(const DeviceArray&) = delete;
  DeviceArray& operator=(const DeviceArray&) = delete;
  DeviceArray(DeviceArray&& other) noexcept : data_(other.data_), count_(other.count_) { other.data_ = nullptr; }
  DeviceArray& operator=(DeviceArray&& other) noexcept {
    std::swap(data_, other.data_);
    std::swap(count_, other.count_);
    return *this;
  }
  T* get() const { return data_; }
  size_t size() const { return count_; }

 private:
  T* data_ = nullptr;
  size_t count_ = 0;
};

template <typename T>
DeviceArray<T> Upload(const T* host, size_t count) {
  DeviceArray<T> device(count);
  if (count > 0) PROCAM_CUDA(cudaMemcpy(device.get(), host, count * sizeof(T), cudaMemcpyHostToDevice));
  return device;
}
template <typename T>
DeviceArray<T> Upload(const std::vector<T>& host) {
  return Upload(host.data(), host.size());
}

}  // namespace procam::cuda
