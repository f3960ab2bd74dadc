// The .mlfeh v4 value and mark streams (docs/mlfeh-v4.md). The values are v3's quantized
// hierarchical surpluses (the same decoded values, so the bound and the prefix property hold as
// before), each coded as its difference from the surplus a higher-order prediction expects:
// on the samples' lattice, cubic along an axis where the four collinear neighbours are decoded,
// linear where two are (SZ3's multilevel interpolation: X. Liang et al., "SZ3", IEEE Trans. Big
// Data 2022), averaged over the axes. The differences are range coded with contexts from the
// spread of the prediction's inputs and their codes; the marks with the previous two marks as
// context. Private to formats/.
#pragma once
#include <mlfe/core/mesh/hierarchy.h>
#include <mlfe/formats/hierarchy_levels.h>

#include <array>
#include <cstdint>
#include <string>
#include <unordered_map>
#include <vector>

#include "range_coder.h"

namespace mlfe {

/// Vertex ids by lattice point (index space): a dense table while (2^L + 1)^D is at most
/// 2^26 points, else a hash map (L ≤ 21, so a point's key fits 64 bits); larger lattices
/// are not indexed (every vertex is then predicted from its parents).
class LatticeIndex {
 public:
  static constexpr std::uint32_t kNone = 0xFFFFFFFFu;
  LatticeIndex(int dim, int level);
  bool usable() const { return mode_ != Mode::kNone; }
  /// Records v at point i (the first vertex recorded at a point keeps it).
  void insert(const std::array<std::int64_t, 3>& i, std::uint32_t v);
  /// The vertex at i, or kNone (also outside the lattice).
  std::uint32_t find(const std::array<std::int64_t, 3>& i) const;

 private:
  enum class Mode { kNone, kDense, kHash };
  bool key(const std::array<std::int64_t, 3>& i, std::uint64_t* k) const;
  Mode mode_ = Mode::kNone;
  int dim_;
  std::int64_t side_;
  std::vector<std::uint32_t> dense_;
  std::unordered_map<std::uint64_t, std::uint32_t> hash_;
};

/// Codes the values of one hierarchy level by level: T0 (step 0) first, then each step's
/// vertices, every one after the vertices its prediction reads. Each step's stream starts
/// with fresh models; the choice of prediction and the contexts follow the decoded values of
/// the steps before, so the steps are coded (and decoded or observed) in order 0, 1, 2, ….
template <int D>
class PredictedValues {
 public:
  /// The value coding (1 or 3) and the lattice of a file.
  struct Coding {
    bool integer = false;                    ///< coding 3: decoded p + q·(2E + 1); else p + q·2E
    double bound = 0;                        ///< E: > 0 for coding 1, an integer ≥ 0 for coding 3
    bool on_lattice = false;                 ///< the hierarchy is on the samples' lattice (sample_lattice.h)
    int lattice_level = 0;                   ///< its L
    std::array<double, 3> spacing{1, 1, 1};  ///< the lattice's spacing (local frame)
  };

 public:
  explicit PredictedValues(const Coding& coding);
  /// Quantizes u at the vertices [from, to) of step `step` of h (its canonical numbering),
  /// storing the decoded values in d (size ≥ to); returns the step's range-coded stream.
  /// residual false: as quantize_hierarchical (quantize_integer) does, against the linear
  /// prediction (v4 form 0); true: against the prediction the context chose (form 2), so the
  /// coded integer is the quantized residual of that prediction, every value still within the
  /// bound. Throws mlfe::Error as those do.
  std::vector<std::uint8_t> encode(const Hierarchy<D>& h, int step, std::size_t from, std::size_t to,
                                   const std::vector<double>& u, std::vector<double>& d, bool residual);
  /// The inverse: decodes the values of [from, to) into d from the step's bytes. Throws
  /// mlfe::Error ("<path>: …" naming `what`) on truncated or trailing bytes and values out of range.
  void decode(const std::string& path, const char* what, const Hierarchy<D>& h, int step, std::size_t from,
              std::size_t to, const std::uint8_t* p, std::size_t n, std::vector<double>& d, bool residual);
  /// The state encode() or decode() would leave for a step whose values d[from, to) were
  /// stored otherwise (a v3-form level section).
  void observe(const Hierarchy<D>& h, int step, std::size_t from, std::size_t to,
               const std::vector<double>& d);

 private:
  // The linear prediction of the coding (v3's), the higher-order one (the linear one where it
  // has no term; integers: rounded half down), the code the higher-order one expects against
  // the linear one, and the context.
  struct Prediction {
    double real = 0;
    std::int64_t integer = 0;
    double high_real = 0;
    std::int64_t high_integer = 0;
    std::int64_t expected = 0;
    int context = 0;
  };
  std::vector<std::uint32_t> order(const Hierarchy<D>& h, int step, std::size_t from, std::size_t to);
  Prediction predict(const Hierarchy<D>& h, int step, std::uint32_t v, const std::vector<double>& d) const;
  std::array<std::int64_t, 3> lattice_point(const Hierarchy<D>& h, std::uint32_t v) const;
  bool higher_order(const Prediction& p) const;
  std::int64_t chosen(const Prediction& p) const;
  void learn(std::uint32_t v, const Prediction& p, const std::vector<double>& d, bool residual);

  Coding coding_;
  LatticeIndex index_;
  rc::IntegerModels models_;
  std::vector<std::uint32_t> magnitude_;  // min(|coded integer|, 2^16) per decoded vertex
  std::vector<std::uint8_t> class_;       // per vertex: odd axes at its step (0: T0 or off-lattice)
  // Per context: the sums of the codes' magnitudes against the linear prediction and against
  // the higher-order one, halved now and then so they follow the data.
  std::vector<std::array<std::uint64_t, 2>> cost_;
};

/// The marks (0 or 1) of one step as a range-coded stream, each modelled by the two marks
/// before it (siblings are consecutive candidates); decode_marks reads n of them and throws
/// mlfe::Error on truncated or trailing bytes.
std::vector<std::uint8_t> encode_marks(const std::vector<std::uint8_t>& marks);
std::vector<std::uint8_t> decode_marks(const std::string& path, const char* what, std::size_t n,
                                       const std::uint8_t* p, std::size_t bytes);

extern template class PredictedValues<2>;
extern template class PredictedValues<3>;

}  // namespace mlfe
