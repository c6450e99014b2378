// The zone pass on vector lanes (fdm_node/core/src/zone_block.*) against the scalar zone pass:
// the same bits for every instruction set this CPU has, both volumetric averagings, 1 and 2
// threads, and a list whose length is not a multiple of the lane count (its tail runs zone by
// zone).
#include <gtest/gtest.h>
#include <omp.h>

#include <cmath>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "demfdm/fdm/model.hpp"
#include "demfdm/simd/isa.hpp"
#include "test_util.hpp"

namespace demfdm::fdm {
namespace {

// Two elastic groups with different constants (the lanes of one block mix them) and a
// Mohr-Coulomb block (its zones run the scalar kernel), gravity, an irregular mesh, the
// strongbox, and velocities and stresses that make every zone's strain increments differ.
Model make_model(VolumetricAveraging avg, int parallel_threshold) {
  ModelParams p;
  p.materials = {MaterialGroup{test::elastic(1e8, 0.3, 2000.0), std::nullopt},
                 MaterialGroup{test::elastic(3e8, 0.2, 1800.0), Box{{0.0, 0.0, 0.0}, {2.2, 4.0, 1.6}}}};
  Material mc = test::elastic(2e8, 0.25, 1900.0);
  mc.model = Constitutive::kMohrCoulomb;
  mc.cohesion = 2e3;
  mc.friction_deg = 30.0;
  p.materials.push_back(MaterialGroup{mc, Box{{2.6, 0.0, 2.4}, {4.0, 4.0, 4.0}}});
  p.averaging = avg;
  p.parallel_threshold = parallel_threshold;
  Mesh m = generate_mesh(test::small_pocket_params());
  test::perturb_interior(m, 0.1, 7);
  Model model(std::move(m), p);
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-1e-3, 1e-3);
  for (std::size_t g = 0; g < model.mesh().num_points(); ++g)
    model.set_velocity(static_cast<std::int32_t>(g), {u(rng), u(rng), u(rng)});
  model.set_uniform_stress({-2e4, -3e4, -5e4, 1e3, -2e3, 5e2});
  return model;
}

struct State {
  std::vector<double> x, v, s, f;
  std::vector<std::uint8_t> plastic;
};

State run(ZoneKernel kernel, VolumetricAveraging avg, int threads, int parallel_threshold) {
  const int before = omp_get_max_threads();
  omp_set_num_threads(threads);
  Model m = make_model(avg, parallel_threshold);
  m.set_zone_kernel(kernel);
  m.step(40);
  omp_set_num_threads(before);
  State st;
  st.x.assign(m.positions().begin(), m.positions().end());
  st.v.assign(m.velocities().begin(), m.velocities().end());
  st.s.assign(m.tet_stresses().begin(), m.tet_stresses().end());
  st.f.assign(m.zone_forces().begin(), m.zone_forces().end());
  st.plastic.assign(m.plastic_state().begin(), m.plastic_state().end());
  return st;
}

template <class T>
bool same_bits(const std::vector<T>& a, const std::vector<T>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0;
}

void expect_same(const State& a, const State& b, const std::string& what) {
  EXPECT_TRUE(same_bits(a.x, b.x)) << what << ": positions";
  EXPECT_TRUE(same_bits(a.v, b.v)) << what << ": velocities";
  EXPECT_TRUE(same_bits(a.s, b.s)) << what << ": stresses";
  EXPECT_TRUE(same_bits(a.f, b.f)) << what << ": zone forces";
  EXPECT_TRUE(same_bits(a.plastic, b.plastic)) << what << ": plastic bits";
}

// The comparisons below mean something: the stresses move, and in every tetrahedron
// differently from a uniform update.
TEST(ZoneBlock, TheModelExercisesThePass) {
  Model m = make_model(VolumetricAveraging::kPerOverlay, 4096);
  EXPECT_GT(m.mesh().num_zones(), 64u);
  const std::vector<double> s0(m.tet_stresses().begin(), m.tet_stresses().end());
  m.step(5);
  const std::vector<double> s1(m.tet_stresses().begin(), m.tet_stresses().end());
  std::size_t moved = 0;
  for (std::size_t i = 0; i < s0.size(); i += 6) moved += s0[i] != s1[i];
  EXPECT_EQ(moved, s0.size() / 6);
}

TEST(ZoneBlock, EveryInstructionSetGivesTheScalarBits) {
  for (auto avg : {VolumetricAveraging::kPerOverlay, VolumetricAveraging::kPerZone}) {
    const State ref = run(ZoneKernel::kScalar, avg, 1, 4096);
    const std::string a = avg == VolumetricAveraging::kPerZone ? "per zone" : "per overlay";
    expect_same(ref, run(ZoneKernel::kBaseline, avg, 1, 4096), a + ", baseline");
    expect_same(ref, run(ZoneKernel::kAuto, avg, 1, 4096), a + ", auto");
    if (simd::isa_available(simd::Isa::kAvx2)) expect_same(ref, run(ZoneKernel::kAvx2, avg, 1, 4096), a + ", avx2");
    if (simd::isa_available(simd::Isa::kAvx512))
      expect_same(ref, run(ZoneKernel::kAvx512, avg, 1, 4096), a + ", avx512");
  }
}

TEST(ZoneBlock, TwoThreadsGiveTheScalarBits) {
  const State ref = run(ZoneKernel::kScalar, VolumetricAveraging::kPerOverlay, 1, 4096);
  expect_same(ref, run(ZoneKernel::kAuto, VolumetricAveraging::kPerOverlay, 2, 1), "2 threads, auto");
  expect_same(ref, run(ZoneKernel::kScalar, VolumetricAveraging::kPerOverlay, 2, 1), "2 threads, scalar");
}

TEST(ZoneBlock, AnInstructionSetThisCpuLacksIsAnError) {
  if (simd::isa_available(simd::Isa::kAvx512)) GTEST_SKIP() << "this CPU has AVX-512";
  Model m = make_model(VolumetricAveraging::kPerOverlay, 4096);
  m.set_zone_kernel(ZoneKernel::kAvx512);
  EXPECT_THROW(m.step(), std::runtime_error);
}

}  // namespace
}  // namespace demfdm::fdm
