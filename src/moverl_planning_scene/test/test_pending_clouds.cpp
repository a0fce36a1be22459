/**
 * \file test_pending_clouds.cpp
 * \brief admitCloud (pending_clouds.h), without a roscore: what a camera's queue keeps in lockstep and in real time.
 */
#include <gtest/gtest.h>

#include <deque>
#include <limits>
#include <vector>

#include "moverl_planning_scene/pending_clouds.h"

namespace mps = moverl_planning_scene;

namespace {

struct Cloud {
  double stamp;
};
constexpr double kNone = std::numeric_limits<double>::quiet_NaN();

std::vector<double> stamps(const std::deque<Cloud>& q) {
  std::vector<double> out;
  for (const Cloud& c : q) out.push_back(c.stamp);
  return out;
}

std::size_t admit(std::deque<Cloud>* q, double stamp, bool lockstep, double batch = kNone, double flight = kNone) {
  return mps::admitCloud(q, Cloud{stamp}, [](const Cloud& c) { return c.stamp; }, lockstep, 3, batch, flight);
}

}  // namespace

TEST(PendingClouds, LockstepKeepsEveryViewInOrderUpToItsDepth) {
  std::deque<Cloud> q;
  EXPECT_EQ(admit(&q, 1.0, true), 0u);
  EXPECT_EQ(admit(&q, 2.0, true), 0u);
  EXPECT_EQ(admit(&q, 3.0, true), 0u);
  EXPECT_EQ(admit(&q, 4.0, true, 1.0, 1.0), 1u);  // full: the oldest goes, whatever the batch
  EXPECT_EQ(stamps(q), (std::vector<double>{2.0, 3.0, 4.0}));
}

TEST(PendingClouds, RealTimeKeepsTheNewestOnly) {
  std::deque<Cloud> q;
  EXPECT_EQ(admit(&q, 1.0, false), 0u);
  EXPECT_EQ(admit(&q, 2.0, false, 0.5), 1u);  // another batch is open: 1.0 is replaced
  EXPECT_EQ(stamps(q), (std::vector<double>{2.0}));
}

TEST(PendingClouds, RealTimeKeepsACloudOfTheBatchBeingIntegrated) {
  // 1.0 is the open batch's (or the cloud in flight's) instant: it stays, and newer ones replace each other behind it.
  for (const bool open : {true, false}) {
    std::deque<Cloud> q;
    admit(&q, 1.0, false);
    const double batch = open ? 1.0 : kNone, flight = open ? kNone : 1.0;
    EXPECT_EQ(admit(&q, 2.0, false, batch, flight), 0u);
    EXPECT_EQ(admit(&q, 3.0, false, batch, flight), 1u);
    EXPECT_EQ(stamps(q), (std::vector<double>{1.0, 3.0}));
    // Once it is integrated (popped by the integrator) the next cloud replaces the waiting one again.
    q.pop_front();
    EXPECT_EQ(admit(&q, 4.0, false, 3.5), 1u);
    EXPECT_EQ(stamps(q), (std::vector<double>{4.0}));
  }
}
