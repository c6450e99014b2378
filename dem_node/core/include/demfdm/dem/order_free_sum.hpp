// Order-free sums (docs/scaling.md, "Order-free sums"): a sum of doubles whose bits do not depend
// on the order of its terms nor on how they are grouped (threads, MPI ranks). The method is the
// error-free extraction of Rump, Ogita and Oishi (2008, "Accurate floating-point summation part
// I", ExtractVector), used for reproducible sums by Demmel and Nguyen (2013, "Fast reproducible
// floating-point summation"):
//
//   with |x| <= 2^e for every term and at most 2^32 - 2 terms, sigma_1 = 2^(e + 32); each term is
//   split as q = (sigma_1 + x) - sigma_1 (exact), x <- x - q (exact). Every q is a multiple of
//   2^-53 sigma_1 and any partial sum of them stays below sigma_1 in magnitude, so the q's add
//   up exactly in any order and grouping: fold 1 is the same double however it is summed. The
//   rest x is at most 2^-53 sigma_1, and is split again against sigma_2 = 2^-21 sigma_1, and so
//   on for four folds. The result is ((T_1 + T_2) + T_3) + T_4; what is left after the fourth
//   fold (at most 2^(e - 84) per term) is dropped: the error is below n 2^-84 max|x|, far below
//   a double's rounding for a sum of terms of one sign (the measurements), not for a sum whose
//   large terms cancel. (Bounds below 2^-1000 or above 2^968 take the plain sum; far from any
//   physical measurement.)
//
// The bound e must be the same for every part: the largest |term| over all of them (one
// maximum-allreduce on ranks), which is why a sum takes two passes over its terms. The folds of
// several parts are added with plain double additions (an MPI sum): exact, hence order-free.
// The result differs from the plain left-to-right sum in the last bits. A bound that is not
// finite (a NaN or an infinite term) gives the plain sum of the terms in the order added.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <vector>

namespace demfdm::dem {

struct OrderFreeSum {
  static constexpr int kFolds = 4;
  static constexpr int kCountBits = 32;  // at most 2^32 - 2 terms over all parts
  double sigma[kFolds] = {0.0, 0.0, 0.0, 0.0};
  double fold[kFolds] = {0.0, 0.0, 0.0, 0.0};
  int folds = 0;       // boundaries in use (0: every term is 0)
  bool plain = false;  // a bound that is not finite: fold[0] is the plain sum

  /// 2^k for k in the normal range [-1022, 1023], exactly (std::ldexp(1.0, k) without the call).
  static double pow2(int k) {
    const std::uint64_t bits = static_cast<std::uint64_t>(k + 1023) << 52;
    double d;
    std::memcpy(&d, &bits, sizeof d);
    return d;
  }
  /// The e of max_abs = m 2^e with m in [0.5, 1) (std::frexp's), for a finite max_abs > 0: read
  /// from the exponent field of a normal number, from frexp for a subnormal one.
  static int exponent_of(double max_abs) {
    std::uint64_t bits;
    std::memcpy(&bits, &max_abs, sizeof bits);
    const int biased = static_cast<int>((bits >> 52) & 0x7ff);
    if (biased != 0) return biased - 1022;
    int e = 0;
    std::frexp(max_abs, &e);
    return e;
  }
  /// The boundaries for terms with |x| <= max_abs (the largest over every part).
  explicit OrderFreeSum(double max_abs) {
    if (!std::isfinite(max_abs)) {
      plain = true;
      return;
    }
    if (!(max_abs > 0.0)) return;  // every term is +-0: the sum is +0
    const int e = exponent_of(max_abs);  // |x| <= 2^e
    if (e + kCountBits > 1000 || e + kCountBits < -968) {  // beyond any physical sum: plain
      plain = true;
      return;
    }
    // sigma_1 = 2^(e + 32), each next one 2^-21 of the last, while the q's (2^-53 sigma) stay
    // normal (sigma >= 2^-968); every power here is a normal number
    for (int k = e + kCountBits, j = 0; j < kFolds && k >= -968; ++j, k += kCountBits - 53) {
      sigma[j] = pow2(k);
      ++folds;
    }
  }
  [[gnu::always_inline]] void add(double x) {
    if (plain) {
      fold[0] += x;
      return;
    }
    for (int k = 0; k < folds; ++k) {
      const double q = (sigma[k] + x) - sigma[k];
      fold[k] += q;
      x -= q;
    }
  }
  /// Another part's folds (the same boundaries).
  void merge(const OrderFreeSum& o) {
    for (int k = 0; k < kFolds; ++k) fold[k] += o.fold[k];
  }
  double result() const {
    double s = fold[0];
    for (int k = 1; k < kFolds; ++k) s += fold[k];
    return s;
  }
};

/// The largest |x| of the n terms; NaN if any is NaN (the bound of OrderFreeSum).
inline double max_abs_of(const double* x, std::size_t n) {
  double m = 0.0;
  int nan = 0;
#pragma omp simd reduction(max : m) reduction(| : nan)
  for (std::size_t i = 0; i < n; ++i) {
    const double a = std::fabs(x[i]);
    nan |= a != a;
    m = a > m ? a : m;
  }
  return nan ? std::nan("") : m;
}

/// The folds of n terms against the boundaries of `bound` (one part of a sum). Eight lanes of
/// partial folds, added at the end: a grouping like any other, so the same bits, without the
/// chain of dependent additions of one accumulator. `positive`: a term that is not > 0 (0, or
/// NaN) counts as +0 (the mean contact force's rule).
inline OrderFreeSum fold_terms(const double* x, std::size_t n, double bound, bool positive = false) {
  OrderFreeSum s(bound);
  auto term = [positive](double v) { return positive ? (v > 0.0 ? v : 0.0) : v; };
  if (s.plain || s.folds < OrderFreeSum::kFolds) {
    for (std::size_t i = 0; i < n; ++i) s.add(term(x[i]));
    return s;
  }
  constexpr std::size_t L = 8;
  const std::size_t nb = n - n % L;
  const double s0 = s.sigma[0], s1 = s.sigma[1], s2 = s.sigma[2], s3 = s.sigma[3];
  double a0[L] = {}, a1[L] = {}, a2[L] = {}, a3[L] = {};
  for (std::size_t i = 0; i < nb; i += L) {
#pragma omp simd
    for (std::size_t l = 0; l < L; ++l) {
      double v = term(x[i + l]);
      const double q0 = (s0 + v) - s0;
      v -= q0;
      const double q1 = (s1 + v) - s1;
      v -= q1;
      const double q2 = (s2 + v) - s2;
      v -= q2;
      const double q3 = (s3 + v) - s3;
      a0[l] += q0;
      a1[l] += q1;
      a2[l] += q2;
      a3[l] += q3;
    }
  }
  for (std::size_t l = 0; l < L; ++l) {
    s.fold[0] += a0[l];
    s.fold[1] += a1[l];
    s.fold[2] += a2[l];
    s.fold[3] += a3[l];
  }
  for (std::size_t i = nb; i < n; ++i) s.add(term(x[i]));
  return s;
}

/// The largest term > 0 of n (0 and NaN count as 0: the bound of fold_terms(..., positive)).
inline double max_positive_of(const double* x, std::size_t n) {
  double m = 0.0;
#pragma omp simd reduction(max : m)
  for (std::size_t i = 0; i < n; ++i) m = x[i] > m ? x[i] : m;
  return m;
}

/// How many of n terms are > 0.
inline std::size_t count_positive(const double* x, std::size_t n) {
  std::size_t c = 0;
#pragma omp simd reduction(+ : c)
  for (std::size_t i = 0; i < n; ++i) c += x[i] > 0.0;
  return c;
}

/// Many order-free sums at once, from terms that name their sum (`t.slot`, value `t.v`): the
/// bound of each of the S sums (the largest |v|; NaN if one is NaN), then every term folded
/// into its sum (the walls' sums: one World's, or one rank's part of them).
template <class Term>
void slot_bounds(const std::vector<Term>& terms, std::size_t S, std::vector<double>& bound) {
  bound.assign(S, 0.0);
  for (const Term& t : terms) {
    const double a = std::fabs(t.v);
    bound[t.slot] = (a > bound[t.slot] || std::isnan(a)) ? a : bound[t.slot];
  }
}
template <class Term>
void slot_folds(const std::vector<Term>& terms, const std::vector<double>& bound, std::vector<OrderFreeSum>& sums) {
  sums.clear();
  for (double b : bound) sums.emplace_back(b);
  for (const Term& t : terms) sums[t.slot].add(t.v);
}

/// The order-free sum of n terms held in one place.
inline double order_free_total(const double* x, std::size_t n) {
  return fold_terms(x, n, max_abs_of(x, n)).result();
}

}  // namespace demfdm::dem
