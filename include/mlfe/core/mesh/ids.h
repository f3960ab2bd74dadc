// Strongly typed indices (Draco style): a VertexId cannot be passed where an ElemId is
// expected. All are 32-bit; kInvalid marks "none".
#pragma once
#include <cstddef>
#include <cstdint>
#include <functional>
#include <limits>
#include <utility>
#include <vector>

namespace mlfe {

template <class Tag>
struct Index {
  using value_type = std::uint32_t;
  static constexpr value_type kInvalidValue = std::numeric_limits<value_type>::max();
  value_type value = kInvalidValue;

  constexpr Index() = default;
  constexpr explicit Index(value_type v) : value(v) {}
  constexpr bool valid() const { return value != kInvalidValue; }
  constexpr friend bool operator==(Index a, Index b) { return a.value == b.value; }
  constexpr friend bool operator!=(Index a, Index b) { return a.value != b.value; }
  constexpr friend bool operator<(Index a, Index b) { return a.value < b.value; }
  constexpr friend bool operator>(Index a, Index b) { return a.value > b.value; }
  constexpr friend bool operator<=(Index a, Index b) { return a.value <= b.value; }
  static constexpr Index invalid() { return Index(); }
};

/// A vector indexed by one kind of typed index only (Draco's IndexTypeVector): per-vertex data
/// cannot be read with an element id. Iteration and sizing as std::vector; vector() gives the
/// plain array for serialization.
template <class IndexT, class T>
class IndexVector {
 public:
  IndexVector() = default;
  explicit IndexVector(std::vector<T> v) : v_(std::move(v)) {}
  T& operator[](IndexT i) { return v_[i.value]; }
  const T& operator[](IndexT i) const { return v_[i.value]; }
  std::size_t size() const { return v_.size(); }
  bool empty() const { return v_.empty(); }
  void resize(std::size_t n) { v_.resize(n); }
  void resize(std::size_t n, const T& value) { v_.resize(n, value); }
  void reserve(std::size_t n) { v_.reserve(n); }
  std::size_t capacity() const { return v_.capacity(); }
  void push_back(const T& value) { v_.push_back(value); }
  void clear() { v_.clear(); }
  auto begin() { return v_.begin(); }
  auto end() { return v_.end(); }
  auto begin() const { return v_.begin(); }
  auto end() const { return v_.end(); }
  /// The id one past the last element: ids run from IndexT(0) to end_id().
  IndexT end_id() const { return IndexT(static_cast<typename IndexT::value_type>(v_.size())); }
  const std::vector<T>& vector() const { return v_; }
  std::vector<T>& vector() { return v_; }

 private:
  std::vector<T> v_;
};

struct VertexTag {};
struct ElemTag {};
using VertexId = Index<VertexTag>;
/// An element: a triangle in 2D, a tetrahedron in 3D.
using ElemId = Index<ElemTag>;
using TetId = ElemId;
using TriId = ElemId;

}  // namespace mlfe

namespace std {
template <class Tag>
struct hash<mlfe::Index<Tag>> {
  size_t operator()(mlfe::Index<Tag> i) const noexcept { return std::hash<std::uint32_t>()(i.value); }
};
}  // namespace std
