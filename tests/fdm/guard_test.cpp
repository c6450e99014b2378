// Blow-up guard of the FDM (fdm/guard.hpp, docs/stability.md): a NaN injected into a gridpoint
// velocity or a zone stress is named with the gridpoint / zone id and its neighbourhood (the
// zones around the gridpoint, the zones sharing a gridpoint with the zone).
#include <gtest/gtest.h>

#include <limits>
#include <set>
#include <sstream>

#include "demfdm/fdm/guard.hpp"
#include "demfdm/fdm/model.hpp"

using namespace demfdm::fdm;

namespace {
ModelParams small() {
  ModelParams p;
  p.mesh = MeshParams::plain_box(3.0, 3.0, 3.0, 1.0);
  p.gravity_level = 1.0;
  p.strongbox_boundary = true;
  return p;
}

// The zone ids listed in a text's "  zone N ..." lines.
std::set<int> listed_zones(const std::string& text) {
  std::set<int> z;
  std::istringstream is(text);
  std::string line;
  while (std::getline(is, line))
    if (line.rfind("  zone ", 0) == 0) z.insert(std::stoi(line.substr(7)));
  return z;
}

std::set<int> zones_with(const Model& m, std::set<std::int32_t> gps, int except = -1) {
  std::set<int> out;
  auto c = m.connectivity();
  for (std::size_t z = 0; z < m.num_zones(); ++z)
    for (int k = 0; k < 8; ++k)
      if (gps.count(c[8 * z + k]) && static_cast<int>(z) != except) out.insert(static_cast<int>(z));
  return out;
}
}  // namespace

TEST(FdmGuard, CleanModelHasNoFinding) {
  Model m(small());
  m.step(20);
  EXPECT_FALSE(check_finite(m).has_value());
}

TEST(FdmGuard, NaNVelocityNamesTheGridpointAndTheZonesAroundIt) {
  Model m(small());
  m.step(5);
  // An interior gridpoint (8 zones around it).
  std::int32_t g = -1;
  const auto& x = m.mesh().points;  // reference positions (the model has moved under gravity)
  for (std::size_t i = 0; i < m.num_gridpoints(); ++i)
    if (std::abs(x[3 * i] - 1) < 1e-9 && std::abs(x[3 * i + 1] - 1) < 1e-9 && std::abs(x[3 * i + 2] - 1) < 1e-9)
      g = static_cast<std::int32_t>(i);
  ASSERT_GE(g, 0);
  m.set_velocity(g, {0.0, std::numeric_limits<double>::quiet_NaN(), 0.0});
  auto f = check_finite(m);
  ASSERT_TRUE(f.has_value());
  EXPECT_EQ(f->gridpoint, g);
  EXPECT_EQ(f->zone, -1);
  EXPECT_NE(f->cause.find("non-finite velocity"), std::string::npos) << f->cause;
  EXPECT_NE(f->cause.find("gridpoint " + std::to_string(g)), std::string::npos) << f->cause;
  auto around = zones_with(m, {g});
  EXPECT_EQ(around.size(), 8u);
  EXPECT_EQ(listed_zones(f->detail), around) << f->detail;
}

TEST(FdmGuard, NaNStressNamesTheZoneAndItsNeighbours) {
  Model m(small());
  m.step(5);
  const std::int32_t z = 13;  // the centre zone of 3 x 3 x 3
  ASSERT_EQ(m.num_zones(), 27u);
  m.set_zone_stress(z, {0.0, 0.0, std::numeric_limits<double>::quiet_NaN(), 0.0, 0.0, 0.0});
  auto f = check_finite(m);
  ASSERT_TRUE(f.has_value());
  EXPECT_EQ(f->zone, z);
  EXPECT_NE(f->cause.find("non-finite stress in zone 13"), std::string::npos) << f->cause;
  auto c = m.connectivity();
  std::set<std::int32_t> corners(c.begin() + 8 * z, c.begin() + 8 * z + 8);
  auto neighbours = zones_with(m, corners, z);
  EXPECT_EQ(neighbours.size(), 26u);  // every other zone of the 3 x 3 x 3 block touches the centre
  // The zone part of the report comes first: its neighbour lines end where the gridpoint part
  // (a corner of zone 13, whose zone force became NaN with the stress) begins.
  auto text = f->detail.substr(0, f->detail.find("\ngridpoint "));
  auto listed = listed_zones(text);
  listed.erase(z);
  EXPECT_EQ(listed, neighbours);
  EXPECT_TRUE(corners.count(f->gridpoint)) << "the first gridpoint named must be a corner of the zone";
}

// The kinetic-energy jump report names the gridpoint with the largest 1/2 m |v|^2.
TEST(FdmGuard, FastestGridpointHasTheLargestKineticEnergy) {
  Model m(small());
  m.reset_velocities();
  EXPECT_EQ(fastest_gridpoint(m), 0) << "all at rest: the first gridpoint";
  const std::int32_t slow = 21, fast = 42;
  m.set_velocity(slow, {0.0, 0.0, 1.0});
  m.set_velocity(fast, {0.0, 3.0, 0.0});
  const auto mass = m.inertial_masses();
  ASSERT_GT(mass[fast] * 9.0, mass[slow] * 1.0);
  EXPECT_EQ(fastest_gridpoint(m), fast);
}
