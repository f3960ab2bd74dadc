// Edge -> midpoint map of the hierarchy. An open-addressing hash table (linear probing) keyed
// by the two endpoint ids, because refinement asks it billions of times and a node-based
// std::unordered_map costs ~4x the memory (≈ 16 bytes per edge here at load ≤ 0.5).
//
// Contract: keys are unordered vertex pairs {a, b} with a != b. find() is safe to call
// concurrently with other find() calls; insert() is not thread-safe.
#pragma once
#include <mlfe/core/base/check.h>
#include <mlfe/core/mesh/ids.h>

#include <cstdint>
#include <vector>

namespace mlfe {

class EdgeMap {
 public:
  EdgeMap() { rehash(64); }

  static std::uint64_t key(VertexId a, VertexId b) {
    std::uint32_t lo = a.value < b.value ? a.value : b.value;
    std::uint32_t hi = a.value < b.value ? b.value : a.value;
    return (std::uint64_t(hi) << 32) | lo;
  }

  /// The midpoint of edge {a, b}, or invalid.
  VertexId find(VertexId a, VertexId b) const {
    const std::uint64_t k = key(a, b);
    std::size_t i = slot(k);
    while (true) {
      const Slot& s = slots_[i];
      if (s.key() == k) return VertexId(s.value);
      if (s.key() == kEmpty) return VertexId::invalid();
      i = (i + 1) & mask_;
    }
  }

  /// Inserts {a, b} -> mid; the edge must not be present.
  void insert(VertexId a, VertexId b, VertexId mid) {
    MLFE_CHECK(a != b && mid.valid());
    if (2 * (size_ + 1) > slots_.size()) rehash(slots_.size() * 2);
    place(key(a, b), mid.value);
    ++size_;
  }

  /// Removes {a, b}, which must be present (refine() rolling back its own inserts). Backward
  /// shift instead of tombstones, so lookups stay as short as if the edge never was there.
  void erase(VertexId a, VertexId b) {
    const std::uint64_t k = key(a, b);
    std::size_t i = slot(k);
    while (slots_[i].key() != k) {
      MLFE_CHECK_MSG(slots_[i].key() != kEmpty, "erased edge not present");
      i = (i + 1) & mask_;
    }
    // Move later entries of the probe run into the hole unless their home slot lies
    // cyclically in (hole, j]: they would become unreachable otherwise.
    for (std::size_t j = (i + 1) & mask_; slots_[j].key() != kEmpty; j = (j + 1) & mask_) {
      const std::size_t home = slot(slots_[j].key());
      if (((j - home) & mask_) >= ((j - i) & mask_)) {
        slots_[i] = slots_[j];
        i = j;
      }
    }
    slots_[i] = Slot::empty();
    --size_;
  }

  std::size_t size() const { return size_; }
  void reserve(std::size_t n) {
    std::size_t cap = slots_.size();
    while (cap < 2 * n) cap *= 2;
    if (cap != slots_.size()) rehash(cap);
  }
  std::size_t memory_bytes() const { return slots_.capacity() * sizeof(Slot); }

  /// Calls f(a, b, mid) for every entry (in table order: not deterministic across insert orders).
  template <class F>
  void for_each(F&& f) const {
    for (const Slot& s : slots_)
      if (s.key() != kEmpty) f(VertexId(s.lo), VertexId(s.hi), VertexId(s.value));
  }

 private:
  static constexpr std::uint64_t kEmpty = ~std::uint64_t(0);
  // Key and value side by side, so that a hit costs one cache line rather than one in a key
  // array and one in a value array (refinement's look-ups mostly miss the cache); 12 bytes, as
  // the two arrays were.
  struct Slot {
    std::uint32_t lo, hi, value;
    std::uint64_t key() const { return (std::uint64_t(hi) << 32) | lo; }
    static Slot empty() { return {~std::uint32_t(0), ~std::uint32_t(0), 0}; }
  };
  std::size_t slot(std::uint64_t k) const {
    k ^= k >> 33;
    k *= 0xff51afd7ed558ccdULL;
    k ^= k >> 33;
    return std::size_t(k) & mask_;
  }
  void place(std::uint64_t k, std::uint32_t v) {
    std::size_t i = slot(k);
    while (slots_[i].key() != kEmpty) {
      MLFE_CHECK_MSG(slots_[i].key() != k, "edge inserted twice");
      i = (i + 1) & mask_;
    }
    slots_[i] = {std::uint32_t(k & 0xffffffffu), std::uint32_t(k >> 32), v};
  }
  void rehash(std::size_t cap) {
    std::vector<Slot> old(cap, Slot::empty());
    old.swap(slots_);
    mask_ = cap - 1;
    for (const Slot& s : old)
      if (s.key() != kEmpty) place(s.key(), s.value);
  }

  std::vector<Slot> slots_;
  std::size_t mask_ = 0;
  std::size_t size_ = 0;
};

}  // namespace mlfe
