// An allocator that leaves trivially constructible records unwritten on resize().
#pragma once
#include <memory>
#include <new>
#include <type_traits>
#include <utility>

namespace mlfe {

/// An allocator whose value-less construct() default-initialises: resize() of a vector of
/// trivial records leaves them unwritten (no zeroing pass), so their pages are first touched
/// by the parallel loop that fills them.
template <class T>
struct DefaultInit : std::allocator<T> {
  template <class U>
  struct rebind {
    using other = DefaultInit<U>;
  };
  DefaultInit() = default;
  template <class U>
  DefaultInit(const DefaultInit<U>&) noexcept {}
  template <class U>
  void construct(U* p) noexcept(std::is_nothrow_default_constructible<U>::value) {
    ::new (static_cast<void*>(p)) U;
  }
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
};

}  // namespace mlfe
