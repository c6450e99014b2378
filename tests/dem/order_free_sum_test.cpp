// Order-free sums (order_free_sum.hpp; docs/scaling.md): the same bits in any order and any
// grouping of the terms, within rounding of the exact sum; and the World's measurements with
// WorldParams::order_free_sums at any thread count.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "demfdm/dem/order_free_sum.hpp"
#include "demfdm/dem/procedures.hpp"
#include "demfdm/dem/world.hpp"
#include "lattice.hpp"

using namespace demfdm::dem;

namespace {

bool same_bits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

// Terms of mixed signs over 40 orders of magnitude (with a few large ones that cancel).
std::vector<double> mixed_terms(std::mt19937_64& rng, std::size_t n) {
  std::uniform_real_distribution<double> u(-1.0, 1.0), e(-30.0, 10.0);
  std::vector<double> x(n);
  for (double& v : x) v = u(rng) * std::pow(10.0, e(rng));
  x[0] = 3.0e12;
  x[n / 2] = -3.0e12;
  return x;
}

// The sum of the terms in __float128 (113-bit significand), compensated: far below a double's
// rounding for these sizes, the reference.
double reference(const std::vector<double>& x) {
  __float128 s = 0, c = 0;
  for (double v : x) {
    const __float128 y = static_cast<__float128>(v) - c;
    const __float128 t = s + y;
    c = (t - s) - y;
    s = t;
  }
  return static_cast<double>(s);
}

// The boundaries as first written (frexp and ldexp): the reference of the constructor's reading
// of the exponent field.
struct ReferenceSum {
  double sigma[OrderFreeSum::kFolds] = {0.0, 0.0, 0.0, 0.0};
  int folds = 0;
  bool plain = false;
  explicit ReferenceSum(double max_abs) {
    if (!std::isfinite(max_abs)) {
      plain = true;
      return;
    }
    if (!(max_abs > 0.0)) return;
    int e = 0;
    std::frexp(max_abs, &e);
    if (e + 32 > 1000 || e + 32 < -968) {
      plain = true;
      return;
    }
    double s = std::ldexp(1.0, e + 32);
    for (int k = 0; k < OrderFreeSum::kFolds && s >= 0x1p-968; ++k) {
      sigma[k] = s;
      ++folds;
      s = std::ldexp(s, 32 - 53);
    }
  }
};

}  // namespace

// OrderFreeSum's boundaries read from the bound's exponent field (frexp only for a subnormal)
// and built as powers of two without ldexp, against the reference above: the same sigmas, fold
// count and plain flag for bounds over the whole double range (subnormal, powers of two and
// their neighbours, the edges of the plain range). (The folds read only these.)
TEST(OrderFreeSum, BoundariesAreTheReferenceAlgorithms) {
  std::mt19937_64 rng(11);
  std::vector<double> bounds = {0.0, -0.0, 0x1p-1074, 0x1p-1060, 3.3e-310, 0x1p-1022, 0x1p-1001, 0x1p-1000,
                                0x1p-999, 0x1p-940, 0x1p-937, 0x1p-936, 1e-300, 0.5, 1.0, 0x1p967, 0x1p968,
                                0x1p969, 1e300, 1.7976931348623157e308, std::nan(""),
                                std::numeric_limits<double>::infinity()};
  std::uniform_real_distribution<double> m(0.5, 1.0);
  std::uniform_int_distribution<int> ex(-1070, 1023);
  for (int k = 0; k < 400; ++k) bounds.push_back(std::ldexp(m(rng), ex(rng)));
  for (int k = -1070; k <= 1023; k += 7) {
    const double p = std::ldexp(1.0, k);
    bounds.insert(bounds.end(), {p, std::nextafter(p, 0.0), std::nextafter(p, 1e308)});
  }
  int four = 0;
  for (const double b : bounds) {
    const OrderFreeSum got(b);
    const ReferenceSum want(b);
    ASSERT_EQ(got.folds, want.folds) << "bound " << b;
    ASSERT_EQ(got.plain, want.plain) << "bound " << b;
    for (int k = 0; k < OrderFreeSum::kFolds; ++k) ASSERT_TRUE(same_bits(got.sigma[k], want.sigma[k])) << "bound " << b;
    four += got.folds == OrderFreeSum::kFolds;
  }
  EXPECT_GT(four, 300) << "most bounds take four folds";
}

// Every order and every grouping into parts (each part folded with the common bound, the parts'
// folds added in any order) gives the same bits; the result is within one rounding of the exact
// sum (the dropped remainder is below 2^-84 of the first boundary), where the plain sum of the
// same terms is far off after the large pair cancels.
TEST(OrderFreeSum, SameBitsInAnyOrderAndGroupingNearTheExactSum) {
  std::mt19937_64 rng(21);
  for (std::size_t n : {3u, 100u, 10000u}) {
    std::vector<double> x = mixed_terms(rng, n);
    const double bound = max_abs_of(x.data(), x.size());
    const double want = order_free_total(x.data(), x.size());
    for (int trial = 0; trial < 5; ++trial) {
      std::vector<double> y = x;
      std::shuffle(y.begin(), y.end(), rng);
      ASSERT_TRUE(same_bits(order_free_total(y.data(), y.size()), want)) << n << " terms, shuffled";
      for (std::size_t parts : {2u, 3u, 7u, 64u}) {
        std::vector<OrderFreeSum> p;
        for (std::size_t k = 0; k < parts; ++k) {
          const std::size_t b = y.size() * k / parts, e = y.size() * (k + 1) / parts;
          p.push_back(fold_terms(y.data() + b, e - b, bound));
        }
        std::shuffle(p.begin(), p.end(), rng);
        OrderFreeSum all(bound);
        for (const OrderFreeSum& q : p) all.merge(q);
        ASSERT_TRUE(same_bits(all.result(), want)) << n << " terms in " << parts << " parts";
      }
    }
    // the bound of the header: a rounding of the result plus n 2^-84 max|x| (the large pair
    // cancels here, so the second part decides for 3 terms)
    const double ref = reference(x);
    EXPECT_LE(std::abs(want - ref), std::abs(ref) * 0x1p-52 + double(n) * bound * 0x1p-84)
        << n << " terms: " << want << " against " << ref;
    // terms of one sign (the measurements' case): within a rounding of the exact sum
    std::vector<double> a(x.size());
    for (std::size_t k = 0; k < x.size(); ++k) a[k] = std::abs(x[k]);
    const double ra = reference(a);
    EXPECT_LE(std::abs(order_free_total(a.data(), a.size()) - ra), ra * 0x1p-52) << n << " positive terms";
  }
  // many terms near the bound (the partial sums grow to n max|x|: the room the count bits keep)
  {
    std::uniform_real_distribution<double> u(0.5, 1.0);
    std::vector<double> y(20000);
    for (double& v : y) v = u(rng) * 1e3;
    const double want = order_free_total(y.data(), y.size());
    for (int trial = 0; trial < 5; ++trial) {
      std::shuffle(y.begin(), y.end(), rng);
      ASSERT_TRUE(same_bits(order_free_total(y.data(), y.size()), want)) << "terms near the bound, shuffled";
    }
  }
  // cancellation: the plain sums of these orders differ, the order-free one is exact
  const double c[] = {1e16, 1.0, -1e16, 0.25};
  EXPECT_EQ(order_free_total(c, 4), 1.25);
  const double d[] = {-1e16, 0.25, 1.0, 1e16};
  EXPECT_EQ(order_free_total(d, 4), 1.25);
  EXPECT_NE((((1e16 + 1.0) + -1e16) + 0.25), 1.25);  // the plain sum loses the 1
}

TEST(OrderFreeSum, ZerosNaNAndInfinity) {
  const double z[] = {0.0, -0.0, 0.0};
  EXPECT_TRUE(same_bits(order_free_total(z, 3), 0.0));
  const double n[] = {1.0, std::nan(""), 2.0};
  EXPECT_TRUE(std::isnan(order_free_total(n, 3)));
  const double i[] = {1.0, INFINITY, 2.0};
  EXPECT_EQ(order_free_total(i, 3), INFINITY);
  const double t[] = {1e-300, 3e-300};  // tiny terms: one fold whose boundary stays normal
  EXPECT_NEAR(order_free_total(t, 2), 4e-300, 1e-5 * 4e-300);
}

// The World's measurements with order_free_sums: the same bits at 1 and 2 threads (4,096 balls
// and more take the threaded paths), within 1e-13 of the plain sums.
TEST(OrderFreeSum, WorldMeasurementsSameBitsAtAnyThreadCount) {
  WorldParams p;
  p.periodic.enabled = true;
  p.periodic.origin = {0, 0, 0};
  const int side = 18;  // 5,832 balls
  const double r = 1e-4, s = 1.96 * r;
  p.periodic.length = {side * s, side * s, side * s};
  p.dt_fixed = 5e-8;
  p.gravity = true;
  p.order_free_sums = true;
  World w(p);
  std::mt19937_64 rng(3);
  test::add_jittered_lattice(w, side, s, r, 0.03 * r, 0.04, rng);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (std::size_t i = 0; i < w.num_balls(); ++i) {
    w.balls().v[i] = 0.05 * Vec3{u(rng), u(rng), u(rng)};
    w.balls().w[i] = 300.0 * Vec3{u(rng), u(rng), u(rng)};
  }
  w.prepare();
  w.step(20);
  double ke[2], fc[2], ratio[2], skel[2];
  for (int t = 0; t < 2; ++t) {
    w.mutable_params().threads = t + 1;
    ke[t] = w.kinetic_energy();
    fc[t] = w.mean_contact_force();
    ratio[t] = w.unbalanced_ratio(fc[t]);
    skel[t] = skeleton_ratio(w, fc[t]).ratio;
  }
  EXPECT_TRUE(same_bits(ke[0], ke[1]));
  EXPECT_TRUE(same_bits(fc[0], fc[1]));
  EXPECT_TRUE(same_bits(ratio[0], ratio[1]));
  EXPECT_TRUE(same_bits(skel[0], skel[1]));
  EXPECT_GT(fc[0], 0.0);
  w.mutable_params().order_free_sums = false;
  w.mutable_params().threads = 1;
  const double ke_plain = w.kinetic_energy(), fc_plain = w.mean_contact_force();
  EXPECT_NEAR(ke[0], ke_plain, 1e-13 * ke_plain);
  EXPECT_NEAR(fc[0], fc_plain, 1e-13 * fc_plain);
  EXPECT_NEAR(ratio[0], w.unbalanced_ratio(fc_plain), 1e-12 * ratio[0]);
  EXPECT_NEAR(skel[0], skeleton_ratio(w, fc_plain).ratio, 1e-12 * skel[0]);
}
