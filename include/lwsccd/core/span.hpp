// lwsccd — a minimal non-owning view of a contiguous range (C++17 has no std::span).
#pragma once

#include <cstddef>
#include <type_traits>
#include <utility>

#include "lwsccd/core/config.hpp"

namespace lwsccd {

template <class T>
class Span {
 public:
  LWSCCD_HD constexpr Span() : data_(nullptr), size_(0) {}
  LWSCCD_HD constexpr Span(T* data, std::size_t size) : data_(data), size_(size) {}
  /// A view of a contiguous container of T (std::vector, std::array, ...).
  template <class Container,
            class = std::enable_if_t<std::is_convertible<decltype(std::declval<Container&>().data()), T*>::value>>
  Span(Container& c) : data_(c.data()), size_(c.size()) {}  // NOLINT: implicit like std::span

  LWSCCD_HD constexpr T* data() const { return data_; }
  LWSCCD_HD constexpr std::size_t size() const { return size_; }
  LWSCCD_HD constexpr bool empty() const { return size_ == 0; }
  LWSCCD_HD constexpr T* begin() const { return data_; }
  LWSCCD_HD constexpr T* end() const { return data_ + size_; }
  LWSCCD_HD constexpr T& operator[](std::size_t i) const { return data_[i]; }

 private:
  T* data_;
  std::size_t size_;
};

}  // namespace lwsccd
