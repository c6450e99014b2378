// io::ModelClock: the model time of the results frames (docs/output.md "Time").
#include "demfdm/io/model_time.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

namespace demfdm::io {
namespace {

// generate, servo, bond, replicate, couple, penetrate: the first four are preparation
// (schema::actions(), tested in tests/config).
const std::vector<bool> kFooting{true, true, true, true, false, false};

TEST(ModelClock, OriginAtTheFirstStageThatIsNotPreparation) {
  ModelClock c(kFooting);
  EXPECT_EQ(c.first_model_stage(), 4u);
  // The DEM's preparation: frames at its own times, the origin still unknown.
  const std::vector<double> node{0.5, 0.625, 0.75, 1.0};
  for (std::size_t i = 0; i < 4; ++i) {
    EXPECT_FALSE(c.stage_begins(i, node[i] - 0.1));
    EXPECT_EQ(c.frame_time(node[i]), node[i]);
  }
  EXPECT_FALSE(c.known());
  EXPECT_TRUE(c.stage_begins(4, 1.0));
  EXPECT_TRUE(c.known());
  EXPECT_EQ(c.origin(), 1.0);
  EXPECT_EQ(c.take_pending_times(), (std::vector<double>{-0.5, -0.375, -0.25, 0.0}));
  EXPECT_TRUE(c.take_pending_times().empty());
  EXPECT_EQ(c.frame_time(1.0), 0.0);
  EXPECT_FALSE(c.stage_begins(5, 2.0)) << "set once";
  EXPECT_EQ(c.origin(), 1.0);
}

TEST(ModelClock, NodesGrantedTheSameStepsWriteBitIdenticalTimes) {
  // The DEM's clock stands at a "long preparation" time, the continuum's at 0 and it
  // sub-cycles each step in three; both get the same grants.
  ModelClock dem(kFooting), fdm(kFooting);
  double t_dem = 0.1234567890123, t_fdm = 0.0;
  dem.stage_begins(4, t_dem);
  fdm.stage_begins(4, t_fdm);
  bool naive_differs = false;
  for (int step = 1; step <= 2000; ++step) {
    const double dt = 1e-7 * (1.0 + 0.37 * std::sin(0.01 * step));
    double b = t_dem;
    t_dem += dt;
    dem.advanced(b, dt, t_dem);
    b = t_fdm;
    for (int k = 0; k < 3; ++k) t_fdm += dt / 3;
    fdm.advanced(b, dt, t_fdm);
    ASSERT_EQ(dem.frame_time(t_dem), fdm.frame_time(t_fdm)) << "step " << step;
    naive_differs = naive_differs || (t_dem - dem.origin()) != (t_fdm - fdm.origin());
  }
  EXPECT_TRUE(naive_differs) << "node time - origin alone would not line the frames up";
}

TEST(ModelClock, StepsTheNodeTakesOnItsOwnAndGrantsWithoutLengthCount) {
  ModelClock c(std::vector<bool>{true, false});  // generate, ucs
  c.frame_time(2.0);
  EXPECT_TRUE(c.stage_begins(1, 3.0));
  EXPECT_EQ(c.take_pending_times(), (std::vector<double>{-1.0}));
  // A UCS test steps inside the stage set-up: the frame at its end is at its own time.
  EXPECT_EQ(c.frame_time(3.5), 0.5);
  c.advanced(3.5, 0.25, 3.75);  // a grant of 0.25 s
  EXPECT_EQ(c.frame_time(3.75), 0.75);
  c.advanced(3.75, 0.0, 4.75);  // a grant without a length: the node's own step
  EXPECT_EQ(c.frame_time(4.75), 1.75);
  c.advanced(5.0, 0.5, 5.5);  // own steps before the grant are caught up first
  EXPECT_EQ(c.frame_time(5.5), 2.5);
}

TEST(ModelClock, NodeOutsideTheFirstModelStageTakesItsTimeAtItsNextStage) {
  // A continuum-only geostatic stage first, the DEM prepares its specimen afterwards: the
  // DEM has not stepped since model time 0, its generation frames are at positive times.
  ModelClock dem(std::vector<bool>{false, true, false});  // geostatic, generate, couple
  EXPECT_EQ(dem.first_model_stage(), 0u);
  EXPECT_TRUE(dem.stage_begins(1, 0.0));
  EXPECT_EQ(dem.frame_time(0.25), 0.25);
}

TEST(ModelClock, PreparationOnlyKeepsTheNodeTimeAndStateRoundTrips) {
  ModelClock prep(std::vector<bool>{true, true});  // generate, servo
  EXPECT_EQ(prep.first_model_stage(), 2u);
  EXPECT_FALSE(prep.stage_begins(1, 1.0));
  EXPECT_EQ(prep.frame_time(1.5), 1.5);

  ModelClock a(kFooting);
  a.frame_time(0.5);
  ModelClock b(kFooting);
  b.set_state(a.state());
  EXPECT_TRUE(b.stage_begins(4, 1.0));
  EXPECT_EQ(b.take_pending_times(), (std::vector<double>{-0.5}));
  b.advanced(1.0, 0.125, 1.125);
  ModelClock c(kFooting);
  c.set_state(b.state());
  EXPECT_EQ(c.frame_time(1.125), 0.125);
  EXPECT_EQ(c.origin(), 1.0);
  c.forget_pending();
  EXPECT_TRUE(c.take_pending_times().empty());
}

}  // namespace
}  // namespace demfdm::io
