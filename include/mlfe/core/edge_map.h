// Edge -> midpoint map of the hierarchy. An open-addressing hash table (linear probing) keyed
// by the two endpoint ids, because refinement asks it billions of times and a node-based
// std::unordered_map costs ~4x the memory (≈ 16 bytes per edge here at load ≤ 0.5).
//
// Contract: keys are unordered vertex pairs {a, b} with a != b. find() is safe to call
// concurrently with other find() calls; insert() is not thread-safe.
#pragma once
#include <mlfe/core/check.h>
#include <mlfe/core/ids.h>

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
      const std::uint64_t s = keys_[i];
      if (s == k) return VertexId(values_[i]);
      if (s == kEmpty) return VertexId::invalid();
      i = (i + 1) & mask_;
    }
  }

  /// Inserts {a, b} -> mid; the edge must not be present.
  void insert(VertexId a, VertexId b, VertexId mid) {
    MLFE_CHECK(a != b && mid.valid());
    if (2 * (size_ + 1) > keys_.size()) rehash(keys_.size() * 2);
    place(key(a, b), mid.value);
    ++size_;
  }

  /// Removes {a, b}, which must be present (refine() rolling back its own inserts). Backward
  /// shift instead of tombstones, so lookups stay as short as if the edge never was there.
  void erase(VertexId a, VertexId b) {
    const std::uint64_t k = key(a, b);
    std::size_t i = slot(k);
    while (keys_[i] != k) {
      MLFE_CHECK_MSG(keys_[i] != kEmpty, "erased edge not present");
      i = (i + 1) & mask_;
    }
    // Move later entries of the probe run into the hole unless their home slot lies
    // cyclically in (hole, j]: they would become unreachable otherwise.
    for (std::size_t j = (i + 1) & mask_; keys_[j] != kEmpty; j = (j + 1) & mask_) {
      const std::size_t home = slot(keys_[j]);
      if (((j - home) & mask_) >= ((j - i) & mask_)) {
        keys_[i] = keys_[j];
        values_[i] = values_[j];
        i = j;
      }
    }
    keys_[i] = kEmpty;
    --size_;
  }

  std::size_t size() const { return size_; }
  void reserve(std::size_t n) {
    std::size_t cap = keys_.size();
    while (cap < 2 * n) cap *= 2;
    if (cap != keys_.size()) rehash(cap);
  }
  std::size_t memory_bytes() const { return keys_.capacity() * 8 + values_.capacity() * 4; }

  /// Calls f(a, b, mid) for every entry (in table order: not deterministic across insert orders).
  template <class F>
  void for_each(F&& f) const {
    for (std::size_t i = 0; i < keys_.size(); ++i)
      if (keys_[i] != kEmpty)
        f(VertexId(std::uint32_t(keys_[i] & 0xffffffffu)), VertexId(std::uint32_t(keys_[i] >> 32)),
          VertexId(values_[i]));
  }

 private:
  static constexpr std::uint64_t kEmpty = ~std::uint64_t(0);
  std::size_t slot(std::uint64_t k) const {
    k ^= k >> 33;
    k *= 0xff51afd7ed558ccdULL;
    k ^= k >> 33;
    return std::size_t(k) & mask_;
  }
  void place(std::uint64_t k, std::uint32_t v) {
    std::size_t i = slot(k);
    while (keys_[i] != kEmpty) {
      MLFE_CHECK_MSG(keys_[i] != k, "edge inserted twice");
      i = (i + 1) & mask_;
    }
    keys_[i] = k;
    values_[i] = v;
  }
  void rehash(std::size_t cap) {
    std::vector<std::uint64_t> old_keys(cap, kEmpty);
    std::vector<std::uint32_t> old_values(cap);
    old_keys.swap(keys_);
    old_values.swap(values_);
    mask_ = cap - 1;
    for (std::size_t i = 0; i < old_keys.size(); ++i)
      if (old_keys[i] != kEmpty) place(old_keys[i], old_values[i]);
  }

  std::vector<std::uint64_t> keys_;
  std::vector<std::uint32_t> values_;
  std::size_t mask_ = 0;
  std::size_t size_ = 0;
};

}  // namespace mlfe
