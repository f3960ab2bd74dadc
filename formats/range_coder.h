// An adaptive binary range coder (the carry-less-cache coder of LZMA, I. Pavlov; each bit's
// probability the mean of a fast and a slow estimate, 16 bits adapted by shifts of 4 and 7) and on top of it
// the coding of signed integers with context models, for the .mlfeh v4 value and mark streams
// (docs/mlfeh-v4.md). Private to formats/.
#pragma once
#include <mlfe/core/base/check.h>
#include <mlfe/core/base/error.h>

#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

namespace mlfe::rc {

constexpr int kProbBits = 12;
constexpr std::uint32_t kTop = 1u << 24;

/// The probability that the next bit of its context is 0: two estimates in 1/65536, one
/// following recent bits (shift 4), one the longer run (shift 7); the coder uses their mean.
struct BitModel {
  std::uint16_t fast = 1u << 15, slow = 1u << 15;
  std::uint32_t p0() const {
    // In 1/4096, kept inside (0, 4096) so neither bit ever gets an empty interval.
    const std::uint32_t p = (std::uint32_t(fast) + slow) >> 5;
    return std::min<std::uint32_t>(std::max<std::uint32_t>(p, 1), (1u << kProbBits) - 1);
  }
  void update(int b) {
    if (b == 0) {
      fast = static_cast<std::uint16_t>(fast + ((65535u - fast) >> 4));
      slow = static_cast<std::uint16_t>(slow + ((65535u - slow) >> 7));
    } else {
      fast = static_cast<std::uint16_t>(fast - (fast >> 4));
      slow = static_cast<std::uint16_t>(slow - (slow >> 7));
    }
  }
};

class Encoder {
 public:
  void bit(BitModel& m, int b) {
    const std::uint32_t bound = (range_ >> kProbBits) * m.p0();
    if (b == 0) {
      range_ = bound;
    } else {
      low_ += bound;
      range_ -= bound;
    }
    m.update(b);
    normalize();
  }
  /// `n` (≤ 32) bits of `v`, most significant first, each with probability 1/2.
  void direct(std::uint32_t v, int n) {
    for (int i = n - 1; i >= 0; --i) {
      range_ >>= 1;
      if ((v >> i) & 1u) low_ += range_;
      normalize();
    }
  }
  /// Flushes the coder; the bytes are complete after this (call once).
  std::vector<std::uint8_t> finish() {
    for (int i = 0; i < 5; ++i) shift_low();
    return std::move(out_);
  }

 private:
  void normalize() {
    while (range_ < kTop) {
      range_ <<= 8;
      shift_low();
    }
  }
  void shift_low() {
    if (static_cast<std::uint32_t>(low_) < 0xFF000000u || (low_ >> 32) != 0) {
      const auto carry = static_cast<std::uint8_t>(low_ >> 32);
      if (pending_) out_.push_back(static_cast<std::uint8_t>(cache_ + carry));
      for (; cache_size_ > 0; --cache_size_) out_.push_back(static_cast<std::uint8_t>(0xFF + carry));
      cache_ = static_cast<std::uint8_t>(low_ >> 24);
      pending_ = true;
    } else {
      ++cache_size_;
    }
    low_ = (low_ & 0x00FFFFFFu) << 8;
  }
  std::uint64_t low_ = 0;
  std::uint32_t range_ = 0xFFFFFFFFu;
  std::uint8_t cache_ = 0;
  bool pending_ = false;  // the first shift_low has no byte to emit (LZMA's leading 0 dropped)
  std::uint64_t cache_size_ = 0;
  std::vector<std::uint8_t> out_;
};

/// Decodes what Encoder wrote. Reading past the end of the bytes throws mlfe::Error
/// ("<path>: truncated <what>"); done() says whether exactly all bytes were used.
class Decoder {
 public:
  Decoder(const std::string& path, const char* what, const std::uint8_t* p, std::size_t n)
      : path_(path), what_(what), p_(p), end_(p + n) {
    for (int i = 0; i < 4; ++i) code_ = (code_ << 8) | next();
  }
  int bit(BitModel& m) {
    const std::uint32_t bound = (range_ >> kProbBits) * m.p0();
    int b;
    if (code_ < bound) {
      range_ = bound;
      b = 0;
    } else {
      code_ -= bound;
      range_ -= bound;
      b = 1;
    }
    m.update(b);
    normalize();
    return b;
  }
  std::uint32_t direct(int n) {
    std::uint32_t v = 0;
    for (int i = 0; i < n; ++i) {
      range_ >>= 1;
      const std::uint32_t b = code_ >= range_ ? 1u : 0u;
      code_ -= range_ & (0u - b);
      v = (v << 1) | b;
      normalize();
    }
    return v;
  }
  /// The encoder's flush leaves exactly 4 bytes past the last one decoding needs.
  bool done() const { return p_ == end_; }

 private:
  void normalize() {
    while (range_ < kTop) {
      range_ <<= 8;
      code_ = (code_ << 8) | next();
    }
  }
  std::uint32_t next() {
    if (p_ == end_) throw Error(path_ + ": truncated " + what_);
    return *p_++;
  }
  const std::string& path_;
  const char* what_;
  const std::uint8_t* p_;
  const std::uint8_t* end_;
  std::uint32_t code_ = 0, range_ = 0xFFFFFFFFu;
};

/// Signed integers below 2^62 in magnitude, binarized as: zero?, sign, the bit length n of the
/// magnitude in unary, the two bits below the leading one (modelled per n, the second also per
/// the first), the rest as direct bits. One model set per context.
class IntegerModels {
 public:
  static constexpr int kMaxLength = 62;
  explicit IntegerModels(int contexts) : m_(static_cast<std::size_t>(contexts)) {}

  template <class Coder>
  void encode(Coder& e, int ctx, std::int64_t q) {
    Models& m = m_[static_cast<std::size_t>(ctx)];
    e.bit(m.zero, q == 0);
    if (q == 0) return;
    e.bit(m.sign, q < 0);
    const std::uint64_t a = q < 0 ? 0 - static_cast<std::uint64_t>(q) : static_cast<std::uint64_t>(q);
    MLFE_CHECK(a < (std::uint64_t(1) << kMaxLength));
    const int n = 64 - __builtin_clzll(a);
    for (int i = 1; i < n; ++i) e.bit(m.length[std::min(i, kLengthModels - 1)], 1);
    if (n < kMaxLength) e.bit(m.length[std::min(n, kLengthModels - 1)], 0);
    const int ln = std::min(n, kLengthModels - 1);
    const int b1 = n >= 2 ? static_cast<int>((a >> (n - 2)) & 1u) : 0;
    if (n >= 2) e.bit(m.second[ln], b1);
    if (n >= 3) e.bit(m.third[ln][b1], static_cast<int>((a >> (n - 3)) & 1u));
    for (int i = n - 4; i >= 0; i -= 32) {
      const int take = std::min(i + 1, 32);
      e.direct(static_cast<std::uint32_t>((a >> (i + 1 - take)) & ((std::uint64_t(1) << take) - 1)), take);
    }
  }

  std::int64_t decode(Decoder& d, int ctx) {
    Models& m = m_[static_cast<std::size_t>(ctx)];
    if (d.bit(m.zero)) return 0;
    const bool negative = d.bit(m.sign);
    int n = 1;
    while (n < kMaxLength && d.bit(m.length[std::min(n, kLengthModels - 1)])) ++n;
    std::uint64_t a = 1;
    const int ln = std::min(n, kLengthModels - 1);
    if (n >= 2) a = (a << 1) | static_cast<std::uint64_t>(d.bit(m.second[ln]));
    if (n >= 3) a = (a << 1) | static_cast<std::uint64_t>(d.bit(m.third[ln][a & 1u]));
    for (int i = n - 4; i >= 0; i -= 32) {
      const int take = std::min(i + 1, 32);
      a = (a << take) | d.direct(take);
    }
    return negative ? -static_cast<std::int64_t>(a) : static_cast<std::int64_t>(a);
  }

 private:
  static constexpr int kLengthModels = 24;
  struct Models {
    BitModel zero, sign;
    BitModel length[kLengthModels];
    BitModel second[kLengthModels];
    BitModel third[kLengthModels][2];
  };
  std::vector<Models> m_;
};

}  // namespace mlfe::rc
