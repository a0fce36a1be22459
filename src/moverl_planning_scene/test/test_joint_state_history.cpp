// The self filter's joint-state history, without ROS: which configurations a cloud may have been taken in, waiting
// for a late state, bounded size.
#include <gtest/gtest.h>

#include <chrono>
#include <thread>

#include "moverl_planning_scene/joint_state_history.h"

namespace mps = moverl_planning_scene;

namespace {
std::vector<double> q(double v) { return {v, v}; }
}  // namespace

TEST(JointStateHistory, BeforeAtAndAfterTheCloud) {
  mps::JointStateHistory h(10);
  h.add(100, q(1));
  h.add(200, q(2));
  h.add(300, q(3));  // a lockstep reset: same stamp, another configuration
  h.add(300, q(4));
  h.add(400, q(5));
  h.add(500, q(6));
  std::vector<std::vector<double>> out;
  ASSERT_TRUE(h.around(300, 0.0, &out));
  // Both states at the stamp, the last before it, the first after it.
  EXPECT_EQ(out, (std::vector<std::vector<double>>{q(3), q(4), q(2), q(5)}));
  ASSERT_TRUE(h.around(250, 0.0, &out));
  EXPECT_EQ(out, (std::vector<std::vector<double>>{q(2), q(3)}));
}

TEST(JointStateHistory, WaitsForAStateAtOrAfterTheCloudAndGivesUp) {
  mps::JointStateHistory h(10);
  h.add(100, q(1));
  std::vector<std::vector<double>> out;
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_FALSE(h.around(150, 0.05, &out));  // none came: the cloud must be dropped
  EXPECT_TRUE(out.empty());
  EXPECT_GE(std::chrono::steady_clock::now() - t0, std::chrono::milliseconds(45));
  std::thread late([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    h.add(160, q(2));  // the driver publishes the state the render saw after the cloud
  });
  EXPECT_TRUE(h.around(150, 2.0, &out));
  late.join();
  EXPECT_EQ(out, (std::vector<std::vector<double>>{q(1), q(2)}));
}

TEST(JointStateHistory, KeepsOnlyTheNewest) {
  mps::JointStateHistory h(3);
  for (int k = 1; k <= 5; ++k) h.add(k * 100, q(k));
  EXPECT_EQ(h.size(), 3u);
  std::vector<std::vector<double>> out;
  ASSERT_TRUE(h.around(250, 0.0, &out));
  EXPECT_EQ(out, (std::vector<std::vector<double>>{q(3)}));  // state 2 is gone: 3 is the first after
}

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
