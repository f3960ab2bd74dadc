// Strongly typed indices (Draco style): a VertexId cannot be passed where an ElemId is
// expected. All are 32-bit; kInvalid marks "none".
#pragma once
#include <cstdint>
#include <functional>
#include <limits>

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
